"""Stopping the graph as `ros2 launch` stops it: SIGINT to every process at once, mid-babbling, mid-fit and
mid-attempt. Every process is done within launch's 5 s with status 0, nothing prints an exception, and
the bag holds every tick the rig published, the last of them at baseline."""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from g2p.bags.dataset import load_run
from g2p_interfaces.msg import LearnerEvent
from tests.ros.rosproc import NodeProcess, RosPeer, wait_until
from tests.system.launched import (
    LAUNCH_SIGTERM_TIMEOUT_S,
    LaunchedGraph,
    assert_every_tick_recorded,
    assert_stopped_cleanly,
)

# A short run; the realtime rig plays babbling and attempts in rig time, so each moment lasts seconds.
LEARNER = {"learner.babbling.duration_s": 10.0, "cycle.n_cycles": 4, "search.threshold_mm": -1000.0}


class EventWatch(RosPeer):
    """The learner's events as they are published, for choosing the moment of the stop."""

    def __init__(self) -> None:
        super().__init__("stop_test_events")
        self.events: list[LearnerEvent] = []
        self._arrived = threading.Condition()
        qos = QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=1000,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        self.node.create_subscription(LearnerEvent, "/leg/learner/events", self._on_event, qos)
        self.start()

    def _on_event(self, msg: LearnerEvent) -> None:
        with self._arrived:
            self.events.append(msg)
            self._arrived.notify_all()

    def wait_for(self, event: str, phase: str, timeout_s: float = 120.0) -> None:
        """Wait until the learner published `event` of `phase`."""
        with self._arrived:
            assert self._arrived.wait_for(
                lambda: any(e.event == event and e.phase == phase for e in self.events), timeout_s
            ), f"no {event} of {phase} within {timeout_s:g} s"


def interrupt(graph: LaunchedGraph) -> None:
    """SIGINT to the whole graph: every process exits 0 within launch's 5 s, none prints an exception."""
    stopped = graph.interrupt()
    print(
        "stopped:", ", ".join(f"{name} {how.code} after {how.after_s:.2f} s" for name, how in stopped.items())
    )
    for name, how in stopped.items():
        assert_stopped_cleanly(name, how, graph.log(name))


@pytest.fixture
def events() -> Iterator[EventWatch]:
    watch = EventWatch()
    yield watch
    watch.close()


@pytest.mark.parametrize("moment", ["babbling", "fit", "attempt"])
def test_sigint_to_the_whole_graph_stops_every_node_cleanly(
    moment: str, events: EventWatch, tmp_path: Path
) -> None:
    graph = LaunchedGraph(tmp_path, "sim_realtime", {"learner": LEARNER})
    try:
        if moment == "babbling":
            events.wait_for("phase_start", "babbling")
            time.sleep(3.0)
        elif moment == "fit":  # the initial fit starts as babbling ends
            events.wait_for("phase_end", "babbling")
        else:
            events.wait_for("attempt_start", "exploration")
            time.sleep(1.5)
        interrupt(graph)
    finally:
        graph.close()
    assert_every_tick_recorded(graph.bag, graph.log("sim"))
    run = load_run(graph.bag)
    (end,) = [e for e in run.events if e.event == "run_end"]
    kinds = [e.event for e in run.events]
    if moment == "babbling":
        assert "phase_end" not in kinds and "sequence cancelled" in end.detail["cancelled"]
    elif moment == "fit":
        assert "attempt_start" not in kinds and "fit cancelled" in end.detail["cancelled"]
    else:
        assert kinds.count("attempt_start") == kinds.count("attempt_end") + 1


def test_sigint_mid_babbling_in_fast_simulation_loses_no_tick(events: EventWatch, tmp_path: Path) -> None:
    # The fast rig publishes thousands of ticks a second: the recorder must keep every one to the last.
    graph = LaunchedGraph(tmp_path, "sim", {"learner": {**LEARNER, "learner.babbling.duration_s": 300.0}})
    try:
        events.wait_for("phase_start", "babbling")
        time.sleep(1.0)
        interrupt(graph)
    finally:
        graph.close()
    published = assert_every_tick_recorded(graph.bag, graph.log("sim"))
    # The fast rig ticks only once the learner plays, which waits for the recorder: the bag holds every
    # tick the rig published.
    ticks = load_run(graph.bag).ticks
    assert (len(ticks.stamps_ns), ticks.incomplete) == (published, 0)


def test_a_learner_stopped_while_its_rig_does_not_answer_exits_in_time(
    events: EventWatch, tmp_path: Path
) -> None:
    # Under launch the rig may have exited before the learner's cancel reaches it: the cancel is never
    # answered. Here the rig is frozen (SIGSTOP) mid-attempt, then the learner alone is interrupted.
    graph = LaunchedGraph(tmp_path, "sim_realtime", {"learner": LEARNER})
    try:
        events.wait_for("attempt_start", "exploration")
        time.sleep(1.0)
        sim, learner = graph.procs["sim"], graph.procs["learner"]
        os.kill(sim.pid, signal.SIGSTOP)
        sent = time.monotonic()
        learner.send_signal(signal.SIGINT)
        code = learner.wait(30.0)
        took = time.monotonic() - sent
        os.kill(sim.pid, signal.SIGCONT)
        assert code == 0 and took < LAUNCH_SIGTERM_TIMEOUT_S, (code, took, graph.log("learner")[-3000:])
        interrupt(graph)
    finally:
        graph.close()
    (end,) = [e for e in load_run(graph.bag).events if e.event == "run_end"]
    assert end.detail["cancelled"] == "sequence cancelled (the rig did not answer the cancel)"


def test_a_learner_stopped_as_it_starts_exits_cleanly_in_time(tmp_path: Path) -> None:
    # The learner imports torch in the background from its start: a stop then (the import takes seconds
    # on a loaded machine with a cold page cache) neither waits for the import nor fails on it.
    peer = RosPeer("stop_test_watch")
    peer.start()
    learner = NodeProcess("g2p_learner", "learn", [], tmp_path)
    try:
        wait_until(
            lambda: ("learner", "/leg") in peer.node.get_node_names_and_namespaces(), 60.0, "the learner"
        )
        sent = time.monotonic()
        code = learner.stop(signal.SIGINT, timeout_s=30.0)
        took = time.monotonic() - sent
    finally:
        peer.close()
    log = learner.log()
    assert code == 0 and took < LAUNCH_SIGTERM_TIMEOUT_S, (code, took, log)
    assert "Traceback" not in log and "Error" not in log, log
