"""replay in real processes: record a live stream with `record`, replay it with `replay`, subscribe here.

The stream comes from the fake rig of fake_rig_publisher.py (run as a process); this test process subscribes
raw, in its own rclpy Context, and compares what arrives with the bag, topic by topic and in order.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from g2p.bags import BagReader
from g2p_interfaces.msg import MotorActivation, Treadmill
from tests.ros.rosproc import executable

# Run as a module from the repository's root: as a script, its folder's test packages g2p_interfaces/ and
# g2p_ros/ would hide the installed ones.
FAKE_RIG = [sys.executable, "-m", "tests.ros.fake_rig_publisher"]
TICKS = 600
RECORD_RATE = 300.0  # ticks/s: the bag spans about 2 s
SUBSCRIBER_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=10000, reliability=ReliabilityPolicy.RELIABLE
)
CLASSES = {
    "/leg/joint_states": JointState,
    "/leg/treadmill": Treadmill,
    "/leg/applied_activation": MotorActivation,
}


def run_process(argv: list[str], log: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        argv, stdout=log.open("w"), stderr=subprocess.STDOUT, text=True, env=os.environ.copy()
    )


def finish(proc: subprocess.Popen[str], timeout_s: float = 120) -> int:
    try:
        return proc.wait(timeout=timeout_s)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A bag recorded live from the fake rig by the `record` executable."""
    tmp = tmp_path_factory.mktemp("replay")
    rig = run_process(
        [*FAKE_RIG, "publish", "--ticks", str(TICKS), "--rate", str(RECORD_RATE)],
        tmp / "rig.out",
    )
    recorder = run_process(
        [str(executable("g2p_recorder", "record")), "--ros-args", "-p", f"bags_dir:={tmp / 'bags'}"],
        tmp / "rec.out",
    )
    try:
        assert finish(rig) == 0, (tmp / "rig.out").read_text()
        recorder.send_signal(signal.SIGINT)
        assert finish(recorder) == 0, (tmp / "rec.out").read_text()
    finally:
        for proc in (rig, recorder):
            if proc.poll() is None:
                proc.kill()
                proc.wait(timeout=10)
    (run,) = (tmp / "bags").iterdir()
    return run


class Probe:
    """Raw subscriptions in a context of this process, recording payloads and arrival times."""

    def __init__(self, topics: dict[str, type], best_effort: dict[str, type] | None = None) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node("replay_probe", context=self.context)
        self.executor = EventsExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.received: dict[str, list[bytes]] = {t: [] for t in [*topics, *(best_effort or {})]}
        self.arrivals: list[float] = []
        qos_of = {**{t: SUBSCRIBER_QOS for t in topics}, **{t: 100 for t in best_effort or {}}}
        for topic, cls in {**topics, **(best_effort or {})}.items():
            qos = (
                qos_of[topic]
                if topic in topics
                else QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT)
            )
            self.node.create_subscription(cls, topic, self._callback(topic), qos, raw=True)

    def _callback(self, topic: str) -> Callable[[bytes], None]:
        def on_message(data: bytes) -> None:
            self.received[topic].append(data)
            self.arrivals.append(time.monotonic())

        return on_message

    def spin_until(self, done: Callable[[], bool], timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while not done() and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.05)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


@pytest.fixture
def probe_factory() -> Iterator[list[Probe]]:
    made: list[Probe] = []
    yield made
    for p in made:
        p.close()


def bag_messages(bag: Path, topic: str) -> list[bytes]:
    with BagReader(bag) as reader:
        return [m.data for m in reader.raw_messages([topic])]


def replay(bag: Path, tmp_path: Path, *options: str) -> subprocess.Popen[str]:
    return run_process(
        [str(executable("g2p_recorder", "replay")), str(bag), *options], tmp_path / "replay.out"
    )


def test_replay_delivers_the_recorded_messages_in_order(
    bag: Path, tmp_path: Path, probe_factory: list[Probe]
) -> None:
    rate = 3.0
    outputs = {
        "/replayed/joint_states": JointState,
        "/leg/treadmill": Treadmill,
        "/leg/applied_activation": MotorActivation,
    }
    probe = Probe(outputs)
    probe_factory.append(probe)
    player = replay(
        bag,
        tmp_path,
        "--rate",
        str(rate),
        "--topics",
        *CLASSES,
        "--remap",
        "/leg/joint_states:=/replayed/joint_states",
        "--wait-for-subscribers",
        "30",
    )
    expected = {
        "/replayed/joint_states": bag_messages(bag, "/leg/joint_states"),
        "/leg/treadmill": bag_messages(bag, "/leg/treadmill"),
        "/leg/applied_activation": bag_messages(bag, "/leg/applied_activation"),
    }
    assert all(len(v) == TICKS for v in expected.values())

    def enough() -> bool:
        return all(len(probe.received[t]) >= len(v) for t, v in expected.items())

    probe.spin_until(lambda: enough() or player.poll() is not None, 120)
    probe.spin_until(enough, 10)
    assert finish(player) == 0, (tmp_path / "replay.out").read_text()
    probe.spin_until(lambda: False, 0.2)  # nothing more may arrive
    for topic, want in expected.items():
        got = probe.received[topic]
        assert len(got) == len(want), topic
        cls = outputs[topic]
        assert [deserialize_message(d, cls) for d in got] == [deserialize_message(d, cls) for d in want], (
            topic
        )
    with BagReader(bag) as reader:
        duration_s = reader.duration_ns * 1e-9
        topic_span_ns = [m.timestamp_ns for m in reader.raw_messages(list(CLASSES))]
    span_s = (max(topic_span_ns) - min(topic_span_ns)) * 1e-9
    assert span_s > 1.5 and duration_s >= span_s
    # recorded timing: the player sleeps until each message is due, so it cannot be quicker than span / rate
    assert max(probe.arrivals) - min(probe.arrivals) >= 0.9 * span_s / rate


def test_replay_publishes_bag_time_on_clock(bag: Path, tmp_path: Path, probe_factory: list[Probe]) -> None:
    probe = Probe({"/leg/treadmill": Treadmill}, best_effort={"/clock": Clock})
    probe_factory.append(probe)
    player = replay(
        bag,
        tmp_path,
        "--rate",
        "2",
        "--clock",
        "100",
        "--topics",
        "/leg/treadmill",
        "/clock",
        "--wait-for-subscribers",
        "30",
    )
    probe.spin_until(lambda: len(probe.received["/leg/treadmill"]) >= TICKS or player.poll() is not None, 120)
    probe.spin_until(lambda: len(probe.received["/leg/treadmill"]) >= TICKS, 10)
    assert finish(player) == 0, (tmp_path / "replay.out").read_text()
    clock_ns = [deserialize_message(d, Clock).clock for d in probe.received["/clock"]]
    times = [c.sec * 1_000_000_000 + c.nanosec for c in clock_ns]
    with BagReader(bag) as reader:
        start, end = reader.start_ns, reader.start_ns + reader.duration_ns
    assert len(times) >= 20  # about 100 Hz over about a second of playback
    assert times == sorted(times)
    # bag time (the recorder's clock), not the recorded /clock messages (rig time, about 50 s)
    assert all(start <= t <= end + 100_000_000 for t in times)


def test_replay_loops_until_stopped(bag: Path, tmp_path: Path, probe_factory: list[Probe]) -> None:
    probe = Probe({"/leg/treadmill": Treadmill})
    probe_factory.append(probe)
    player = replay(
        bag, tmp_path, "--rate", "20", "--loop", "--topics", "/leg/treadmill", "--wait-for-subscribers", "30"
    )
    probe.spin_until(
        lambda: len(probe.received["/leg/treadmill"]) >= 2 * TICKS + 10 or player.poll() is not None, 120
    )
    player.send_signal(signal.SIGINT)
    assert finish(player) == 0, (tmp_path / "replay.out").read_text()
    got = [deserialize_message(d, Treadmill).displacement_mm for d in probe.received["/leg/treadmill"]]
    one_pass = [
        deserialize_message(d, Treadmill).displacement_mm for d in bag_messages(bag, "/leg/treadmill")
    ]
    assert len(got) > 2 * TICKS
    assert got[: 2 * TICKS] == one_pass + one_pass


@pytest.mark.parametrize(
    "options, message",
    [
        (["--topics", "/nope"], "not in the bag: /nope"),
        (["--remap", "/leg/treadmill:=/clock", "--clock"], "/clock is published by --clock"),
    ],
)
def test_replay_bad_options_exit_2(bag: Path, tmp_path: Path, options: list[str], message: str) -> None:
    done = subprocess.run(
        [str(executable("g2p_recorder", "replay")), str(bag), *options],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2
    assert len(done.stderr.splitlines()) == 1 and message in done.stderr


def test_replay_of_a_truncated_bag_exits_2_naming_the_file(bag: Path, tmp_path: Path) -> None:
    broken = tmp_path / bag.name
    broken.mkdir()
    for f in bag.iterdir():
        if f.is_file():
            (broken / f.name).write_bytes(f.read_bytes())
    mcap = broken / f"{bag.name}.mcap"
    with mcap.open("r+b") as f:
        f.truncate(mcap.stat().st_size // 2)
    done = subprocess.run(
        [str(executable("g2p_recorder", "replay")), str(broken)], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 2
    assert done.stderr.splitlines() == [
        line for line in done.stderr.splitlines() if line.startswith("replay: error:")
    ]
    assert len(done.stderr.splitlines()) == 1 and str(mcap) in done.stderr
