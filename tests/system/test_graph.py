"""The whole graph as a user runs it: the installed simulator, learner and recorder executables in their
own processes, driven over ROS 2 actions by a client, in fast simulation."""

from __future__ import annotations

import dataclasses
import json
import math
import socket
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from action_msgs.msg import GoalStatus

from g2p.bags import BagReader
from g2p.bags.dataset import load_run, load_training_data
from g2p.inverse_map import InverseMap
from g2p.learning.babbling import BabblingConfig
from g2p.learning.experiments import run_treadmill
from g2p.learning.learner import Learner, LearnerConfig
from g2p.learning.limit_cycle import LimitCycleConfig, attempt_kinematics
from g2p.learning.search import SearchConfig
from g2p.plant import TickSample
from g2p.rig import PlantRig
from g2p.rig.closed_loop import FeedbackConfig, Trajectory, TrajectoryTracker
from g2p.rig.envelope import replay
from g2p.safety import BASELINE_ACTIVATION
from g2p.sim import MujocoLeg, MujocoLegConfig
from g2p_interfaces.action import Attempt, Babble, Learn, Track
from g2p_interfaces.msg import MotorActivation
from g2p_ros import contract
from g2p_ros.action_client import ActionClient
from tests.ros.rosproc import NodeProcess, RosPeer, executable, wait_until
from tests.viewer.foxglove_client import FoxgloveClient

FEATURES = [0.6, 0.5, 0.7, 0.4, 0.6, 0.5, 0.6, 0.7, 0.5, 0.6]
SHORT = ["-p", "learner.babbling.duration_s:=20.0", "-p", "cycle.n_cycles:=4"]


def start_sim(log_dir: Path, namespace: str = "/leg", *extra: str) -> NodeProcess:
    return NodeProcess(
        "g2p_sim", "sim", ["--ros-args", "-r", f"__ns:={namespace}", "-p", "time_mode:=fast", *extra], log_dir
    )


def run_bringup(cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """The installed `bringup` with `args`, run to its end in `cwd`; its output captured."""
    return subprocess.run(
        [str(executable("g2p_bringup", "bringup")), *args],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=cwd,
    )


def start_learner(log_dir: Path, *extra: str) -> NodeProcess:
    return NodeProcess(
        "g2p_learner", "learn", ["--serve", "--ros-args", "-p", "use_sim_time:=true", *SHORT, *extra], log_dir
    )


class LearnerClient(RosPeer):
    """A user's client of the learner's four actions, plus a view of the rig's applied activations."""

    def __init__(self, rig_namespace: str = "/leg") -> None:
        super().__init__("learner_client")
        self.babble = ActionClient(self.node, Babble, "babble")
        self.attempt = ActionClient(self.node, Attempt, "attempt")
        self.learn = ActionClient(self.node, Learn, "learn")
        self.track = ActionClient(self.node, Track, "track")
        self.applied: list[list[float]] = []
        applied = f"{rig_namespace}/{contract.APPLIED_ACTIVATION}"
        self.node.create_subscription(
            MotorActivation, applied, lambda m: self.applied.append(list(m.activation)), 10000
        )
        self.start()
        self.wait_for_servers(
            {
                "babble": self.babble.server_is_ready,
                "attempt": self.attempt.server_is_ready,
                "learn": self.learn.server_is_ready,
                "track": self.track.server_is_ready,
            },
            60.0,
        )
        # The rig's ticks are volatile: see its publisher before anything plays, or miss the first ones.
        wait_until(lambda: self.node.count_publishers(applied) > 0, 60.0, f"a publisher of {applied}")

    def destroy_entities(self) -> None:
        for client in (self.babble, self.attempt, self.learn, self.track):
            client.destroy()

    def send(self, client: ActionClient, goal: object, feedback: list[object] | None = None):
        return self.wait(
            client.send_goal_async(goal, feedback_callback=feedback.append if feedback is not None else None),
            30.0,
        )

    def run(self, client: ActionClient, goal: object, timeout_s: float = 300.0):
        handle = self.send(client, goal)
        assert handle.accepted, f"{type(goal).__name__} rejected"
        return self.wait(handle.get_result_async(), timeout_s)


@pytest.fixture
def graph(tmp_path: Path) -> Iterator[LearnerClient]:
    sim, learner = start_sim(tmp_path), start_learner(tmp_path)
    client = LearnerClient()
    yield client
    client.close()
    for proc in (learner, sim):
        assert proc.stop() == 0, proc.log()


def test_babble_attempts_learn_and_track_through_the_graph(graph: LearnerClient) -> None:
    babbled = graph.run(graph.babble, Babble.Goal(duration_s=20.0))
    assert babbled.status == GoalStatus.STATUS_SUCCEEDED, babbled.result.message
    assert babbled.result.sample_count > 1000 and 0 < babbled.result.validation_rmse < 0.3
    for skip in (False, True):
        done = graph.run(graph.attempt, Attempt.Goal(features=FEATURES, cycles=3, skip_refinement=skip))
        assert done.status == GoalStatus.STATUS_SUCCEEDED
        r = done.result
        assert math.isfinite(r.reward_mm) and r.energy_j > 0 and r.tracking_mse_deg2 > 0
        assert r.refined is not skip
    feedback: list[object] = []
    handle = graph.send(
        graph.learn,
        Learn.Goal(
            babbling_duration_s=20.0, threshold_mm=1000.0, max_exploration_attempts=2, exploitation_attempts=1
        ),
        feedback,
    )
    learned = graph.wait(handle.get_result_async(), 300.0)
    assert learned.status == GoalStatus.STATUS_SUCCEEDED
    assert learned.result.exploration_attempts == 2 and not learned.result.crossed_threshold
    assert [f.feedback.attempt for f in feedback if f.feedback.phase != "babbling"] == [1, 2]
    babbling = [f.feedback.babbling_progress for f in feedback if f.feedback.phase == "babbling"]
    assert babbling[0] == 0.0 and babbling[-1] == 1.0 and babbling == sorted(babbling)  # from its start
    tracked = graph.run(graph.track, Track.Goal(mode=Track.Goal.MODE_REFINE_ONE, refinements=2))
    assert tracked.status == GoalStatus.STATUS_SUCCEEDED and len(tracked.result.attempt_mse_deg2) == 3


def test_invalid_goals_are_rejected(graph: LearnerClient) -> None:
    # No map yet: attempts and tracking need babbling first.
    assert not graph.send(graph.attempt, Attempt.Goal(features=FEATURES)).accepted
    assert not graph.send(graph.babble, Babble.Goal(duration_s=-1.0)).accepted
    assert not graph.send(graph.babble, Babble.Goal(duration_s=math.nan)).accepted
    assert not graph.send(graph.learn, Learn.Goal(dataset_bag="/no/such/bag")).accepted
    assert not graph.send(graph.track, Track.Goal(mode=7)).accepted
    assert graph.run(graph.babble, Babble.Goal(duration_s=10.0)).status == GoalStatus.STATUS_SUCCEEDED
    for bad in (FEATURES[:9], [*FEATURES[:9], 1.5], [*FEATURES[:9], math.nan]):
        assert not graph.send(graph.attempt, Attempt.Goal(features=bad)).accepted, bad
    # A second goal while one runs is rejected.
    running = graph.send(graph.babble, Babble.Goal(duration_s=60.0))
    assert running.accepted
    assert not graph.send(graph.attempt, Attempt.Goal(features=FEATURES)).accepted
    assert graph.wait(running.get_result_async(), 120.0).status == GoalStatus.STATUS_SUCCEEDED


def test_cancel_mid_attempt_drops_the_rig_to_baseline_and_the_learner_goes_on(graph: LearnerClient) -> None:
    assert graph.run(graph.babble, Babble.Goal(duration_s=10.0)).status == GoalStatus.STATUS_SUCCEEDED
    feedback: list[object] = []
    handle = graph.send(graph.attempt, Attempt.Goal(features=FEATURES, cycles=200), feedback)
    wait_until(lambda: any(f.feedback.ticks_done > 200 for f in feedback), 60.0, "the attempt to play")
    graph.wait(handle.cancel_goal_async(), 10.0)
    result = graph.wait(handle.get_result_async(), 30.0)
    assert result.status == GoalStatus.STATUS_CANCELED
    wait_until(lambda: graph.applied[-1] == [0.15] * 3, 10.0, "the rig at baseline")
    ticks_at_cancel = len(graph.applied)
    assert ticks_at_cancel < 200 * 80  # the attempt did not play to its end
    done = graph.run(graph.attempt, Attempt.Goal(features=FEATURES, cycles=2))
    assert done.status == GoalStatus.STATUS_SUCCEEDED and done.result.refined


def test_the_learner_drives_a_rig_in_another_namespace_by_remapping_only(tmp_path: Path) -> None:
    sim = start_sim(tmp_path, "/leg2")
    learner = start_learner(
        tmp_path, "-r", "run_activations:=/leg2/run_activations", "-r", "reset:=/leg2/reset"
    )
    client = LearnerClient(rig_namespace="/leg2")
    try:
        assert client.run(client.babble, Babble.Goal(duration_s=10.0)).status == GoalStatus.STATUS_SUCCEEDED
        # The ticks were played by the rig in /leg2 (the topic may still be delivering when the result lands).
        wait_until(lambda: len(client.applied) >= 10 * 78, 10.0, "the rig in /leg2 to have played the ticks")
    finally:
        client.close()
        codes = [proc.stop() for proc in (learner, sim)]  # both stopped before either is judged
        assert codes == [0, 0], learner.log() + sim.log()


def test_a_goal_waits_for_the_recorder_and_names_it_when_it_never_comes(tmp_path: Path) -> None:
    sim = start_sim(tmp_path)
    learner = start_learner(tmp_path, "-p", "recorder_node:=no_such_recorder", "-p", "rig_timeout_s:=3.0")
    client = LearnerClient()
    try:
        done = client.run(client.babble, Babble.Goal(duration_s=10.0))
        assert done.status == GoalStatus.STATUS_ABORTED
        assert "recorder /leg/no_such_recorder" in done.result.message
        assert all(a == [0.15] * 3 for a in client.applied)  # nothing was played unrecorded
    finally:
        client.close()
        codes = [proc.stop() for proc in (learner, sim)]  # both stopped before either is judged
        assert codes == [0, 0], learner.log() + sim.log()


def test_the_learner_survives_the_rig_restarting_between_goals(tmp_path: Path) -> None:
    sim, learner = start_sim(tmp_path), start_learner(tmp_path)
    client = LearnerClient()
    try:
        assert client.run(client.babble, Babble.Goal(duration_s=10.0)).status == GoalStatus.STATUS_SUCCEEDED
        assert sim.stop() == 0
        sim = start_sim(tmp_path)
        done = client.run(client.attempt, Attempt.Goal(features=FEATURES, cycles=2))
        assert done.status == GoalStatus.STATUS_SUCCEEDED, done.result.message
    finally:
        client.close()
        codes = [proc.stop() for proc in (learner, sim)]  # both stopped before either is judged
        assert codes == [0, 0], learner.log() + sim.log()


def test_make_run_equivalent_records_a_run_whose_map_can_be_rebuilt_from_the_bag(tmp_path: Path) -> None:
    """The bring-up of the main job, shortened; the map rebuilt from the bag equals the recorded one."""
    bags = tmp_path / "bags"
    proc = run_bringup(
        tmp_path,
        "--bags-dir",
        str(bags),
        "--run-id",
        "test-run",
        "--set",
        "learner.learner.babbling.duration_s=20.0",
        "--set",
        "learner.cycle.n_cycles=4",
        "--set",
        "learner.search.max_exploration_attempts=3",
        "--set",
        "learner.search.exploitation_attempts=2",
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "| test-run |" in proc.stdout
    bag = bags / "test-run"
    # Every tick of the run reached the bag on every rig topic, the last ones included (the rig flushes its
    # publishers before it exits).
    with BagReader(bag) as reader:
        stamps = {t: [] for t in contract.RIG_SAMPLE_TOPICS}
        for m in reader.messages([f"/leg/{t}" for t in contract.RIG_SAMPLE_TOPICS]):
            stamps[m.topic.removeprefix("/leg/")].append(
                m.msg.header.stamp.sec * 10**9 + m.msg.header.stamp.nanosec
            )
    played = {t: sorted(v) for t, v in stamps.items()}
    assert all(v == played[contract.JOINT_STATES] for v in played.values()), {
        t: len(v) for t, v in played.items()
    }
    summary = json.loads((bag / "summary.json").read_text())
    run = load_run(bag)
    assert summary["attempt_count"] == len(run.attempts) >= 3
    assert (bag / "report" / "fig4a_reward.png").is_file()
    # Every node's resolved configuration is in the bag.
    assert run.configs["/leg/sim/config"]["time_mode"] == "fast"
    assert run.configs["/leg/sim/config"]["leg"]["calibration"] == ""
    assert run.configs["/leg/recorder/config"]["run_id"] == "test-run"
    # Rebuild the learner's map from the bag alone, with the configuration recorded in it.
    config = run.configs["/leg/learner/config"]["learner"]
    assert config["seed"] == 0
    data = load_training_data(bag)
    learner = Learner(LearnerConfig(seed=config["seed"]))
    learner.fit_babbling(data.babbling)
    for k, recording in enumerate(data.attempts, start=1):
        learner.refine_with(recording, f"attempt {k}")
    recorded = InverseMap.from_arrays(data.inverse_map)
    x = np.random.default_rng(0).normal(size=(200, 6))
    np.testing.assert_array_equal(learner.inverse_map.predict(x), recorded.predict(x))
    # The same run in-process, on a PlantRig over the same simulated leg: the same run, bit for bit.
    in_process = Learner(LearnerConfig(babbling=BabblingConfig(duration_s=20.0)))
    here = run_treadmill(
        in_process,
        PlantRig(MujocoLeg(MujocoLegConfig())),
        SearchConfig(max_exploration_attempts=3, exploitation_attempts=2),
        LimitCycleConfig(n_cycles=4),
    )
    assert [r.outcome.reward_mm for r in here.reports] == [
        e.reward_mm for e in run.events if e.event == "attempt_end"
    ]
    np.testing.assert_array_equal(in_process.inverse_map.predict(x), recorded.predict(x))


def test_bringup_stops_the_run_when_the_recorder_cannot_record(tmp_path: Path) -> None:
    """A recorder that exits at start (it cannot write its bags directory) ends the run, unrecorded."""
    proc = run_bringup(tmp_path, "--bags-dir", "/proc/no-such-dir", "--run-id", "x")
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "recorder exited" in proc.stderr
    assert "babbling" not in proc.stdout  # the learner never started its run


def test_a_closed_loop_run_records_what_the_rig_decided_tick_by_tick(tmp_path: Path) -> None:
    """`learner.control=closed` through the graph: the rig ran the loop, and the bag says so exactly.

    Known answer: the rig's tracker, replayed in-process on the recorded joint states with the map the
    learner had before each attempt, decides the recorded activations and corrections bit for bit.
    """
    bags = tmp_path / "bags"
    proc = run_bringup(
        tmp_path,
        "--bags-dir",
        str(bags),
        "--run-id",
        "closed-run",
        "--set",
        "learner.learner.control=closed",
        "--set",
        "learner.learner.babbling.duration_s=20.0",
        "--set",
        "learner.cycle.n_cycles=4",
        "--set",
        "learner.search.max_exploration_attempts=2",
        "--set",
        "learner.search.exploitation_attempts=1",
        "--no-report",
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    run = load_run(bags / "closed-run")
    config = run.configs["/leg/learner/config"]
    assert config["learner"]["control"] == "closed"
    feedback = FeedbackConfig(**_tuples(config["learner"]["feedback"]))
    cycle = LimitCycleConfig(**_tuples(config["cycle"]))
    lead = config["learner"]["preprocess"]["command_lead_ticks"]
    assert len(run.attempts) >= 2
    maps = {m.refinement: m for m in run.inverse_maps}
    for attempt in run.attempts:
        assert attempt.control == "closed" and attempt.correction_rad_s is not None
        assert attempt.correction_rad_s.shape == (len(attempt.recording), 2)
        assert np.any(attempt.correction_rad_s != 0)
        snapshot = maps[attempt.attempt - 1]  # refined after every attempt: the map this one played
        inverse_map = InverseMap.from_arrays(
            {**snapshot.arrays, "format_version": np.array([float(snapshot.format_version)])}
        )
        assert attempt.end is not None
        desired = attempt_kinematics(attempt.end.features, cycle)
        tracker = TrajectoryTracker(Trajectory(desired, inverse_map, feedback, lead))
        rec = attempt.recording
        decided = [tracker.next_activation(None)]
        for k in range(1, len(rec)):
            measured = TickSample(*(getattr(rec, f.name)[k - 1] for f in dataclasses.fields(TickSample)))
            decided.append(tracker.next_activation(measured))
        # What the rig decided, as its rig_limits recorded it; applied through its safety envelope.
        recorded = run.decided_activation(rec)
        assert recorded is not None
        np.testing.assert_array_equal(np.clip(decided, BASELINE_ACTIVATION, 1.0), recorded)
        np.testing.assert_array_equal(replay(recorded, rec)[1:], rec.activation[1:])
        np.testing.assert_array_equal(tracker.correction_rad_s, attempt.correction_rad_s)


def _tuples(config: dict[str, Any]) -> dict[str, Any]:
    """A recorded configuration section with its lists as the tuples the dataclass takes."""
    return {k: tuple(v) if isinstance(v, list) else v for k, v in config.items()}


def test_bringup_view_serves_the_run_live_to_a_foxglove_client(tmp_path: Path) -> None:
    """`make run ARGS="--view"`: the viewer joins the graph; a client sees every attempt as the bag has it."""
    bags = tmp_path / "bags"
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    client = FoxgloveClient(f"ws://127.0.0.1:{port}", 300, until_close=True)
    proc = run_bringup(
        tmp_path,
        "--view",
        "--bags-dir",
        str(bags),
        "--run-id",
        "viewed-run",
        "--set",
        f"viewer.port={port}",
        "--set",
        "learner.learner.babbling.duration_s=20.0",
        "--set",
        "learner.cycle.n_cycles=4",
        "--set",
        "learner.search.max_exploration_attempts=2",
        "--set",
        "learner.search.exploitation_attempts=1",
        "--no-report",
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    received = client.result()
    assert received.returncode == 0, received.stderr
    run = load_run(bags / "viewed-run")
    shown = [m for _, m in received.messages["/view/attempts"]]
    assert [(m["attempt"], m["reward_mm"]) for m in shown] == [(a.attempt, a.reward_mm) for a in run.attempts]
    for attempt in run.attempts:
        # The learner announces one cycle of the desired angles at the start: the attempt's first cycle.
        cycle = np.array(attempt.start.detail["desired_cycle_rad"])
        assert attempt.desired_position_rad is not None
        np.testing.assert_array_equal(cycle, attempt.desired_position_rad[: len(cycle)])
    joints = [m for _, m in received.messages["/view/joints"] if m["attempt"] == run.attempts[-1].attempt]
    assert joints and all(m["proximal_desired_rad"] is not None for m in joints)
