"""The recorder in real processes: the installed `record` executable against a fake rig publisher process.

The fake rig (tests/ros/fake_rig_publisher.py) publishes deterministic ticks, so the tests can rebuild
every published message and compare it field by field with the bag.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

import pytest
import rclpy
import yaml
from rclpy.serialization import deserialize_message
from std_msgs.msg import String

from g2p.bags import BagReader, recoverable_counts
from tests.commands import console_script
from tests.ros.fake_rig_publisher import (
    CONFIG,
    CONFIG_TOPIC,
    FAST_SIM_DEPTH,
    RELIABLE_TOPICS,
    RIG_TOPICS,
    STAMP0_NS,
    TICK_NS,
    tick_messages,
)
from tests.ros.rosproc import ROOT, executable

# Run as a module from the repository's root: as a script, its folder's test packages g2p_interfaces/ and
# g2p_ros/ would hide the installed ones.
FAKE_RIG = [sys.executable, "-m", "tests.ros.fake_rig_publisher"]

# Test helpers -------------------------------------------------------------------------------------------


class Processes:
    """Processes a test started; whatever still runs at the end is killed (by pid)."""

    def __init__(self, tmp_path: Path) -> None:
        self.tmp_path = tmp_path
        self.started: list[subprocess.Popen[str]] = []
        self._logs: list[IO[str]] = []

    def start(self, name: str, argv: list[str]) -> subprocess.Popen[str]:
        out = open(self.tmp_path / f"{name}.out", "w")
        self._logs.append(out)
        proc = subprocess.Popen(
            argv, stdout=out, stderr=subprocess.STDOUT, text=True, env=os.environ.copy(), cwd=ROOT
        )
        self.started.append(proc)
        return proc

    def log(self, name: str) -> str:
        return (self.tmp_path / f"{name}.out").read_text()

    def stop_all(self) -> None:
        for proc in self.started:
            if proc.poll() is None:
                proc.kill()
                proc.wait(timeout=10)
        for out in self._logs:
            out.close()


@pytest.fixture
def procs(tmp_path: Path) -> Iterator[Processes]:
    p = Processes(tmp_path)
    yield p
    p.stop_all()


def start_publisher(
    procs: Processes,
    ticks: int,
    rate: float = 0.0,
    depth: int = FAST_SIM_DEPTH,
    hold: bool = False,
    wait_for: list[str] | None = None,
) -> subprocess.Popen[str]:
    argv = [
        *FAKE_RIG,
        "publish",
        "--ticks",
        str(ticks),
        "--rate",
        str(rate),
    ]
    argv += ["--depth", str(depth), *(["--hold"] if hold else [])]
    if wait_for is not None:
        argv += ["--wait-for", *wait_for]
    return procs.start("publisher", argv)


def start_recorder(procs: Processes, bags: Path, *params: str) -> subprocess.Popen[str]:
    argv = [str(executable("g2p_recorder", "record")), "--ros-args", "-p", f"bags_dir:={bags}"]
    for p in params:
        argv += ["-p", p]
    return procs.start("recorder", argv)


def published_counts(procs: Processes, proc: subprocess.Popen[str], timeout_s: float = 120) -> dict[str, Any]:
    assert proc.wait(timeout=timeout_s) == 0, procs.log("publisher")
    return json.loads(procs.log("publisher").strip().splitlines()[-1])  # type: ignore[no-any-return]


def stop(procs: Processes, proc: subprocess.Popen[str], sig: int = signal.SIGINT) -> None:
    proc.send_signal(sig)
    assert proc.wait(timeout=60) == 0, procs.log("recorder")


def the_run(bags: Path, timeout_s: float = 30) -> Path:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        runs = [p for p in bags.iterdir()] if bags.is_dir() else []
        if runs:
            (run,) = runs
            return run
        time.sleep(0.05)
    raise AssertionError(f"no run directory appeared in {bags}")


def recorded_by_topic(bag: Path) -> dict[str, list[Any]]:
    """The bag's messages per topic, deserialized by rclpy (CDR padding bytes are not compared)."""
    classes = {topic: type(msg) for topic, msg in tick_messages(0)}
    classes[CONFIG_TOPIC] = classes["/recorder/config"] = String
    out: dict[str, list[Any]] = {}
    with BagReader(bag) as reader:
        for m in reader.raw_messages():
            if m.topic in classes:
                out.setdefault(m.topic, []).append(deserialize_message(m.data, classes[m.topic]))
    return out


def expected_by_topic(ticks: int) -> dict[str, list[Any]]:
    out: dict[str, list[Any]] = {}
    for k in range(ticks):
        for topic, msg in tick_messages(k):
            out.setdefault(topic, []).append(msg)
    return out


def graph_publishers(topics: list[str]) -> dict[str, tuple[str, int, int]]:
    """topic -> (type hash, reliability, durability) of its publisher, seen from a context of this process."""
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node("graph_probe", context=context)
        deadline = time.monotonic() + 30
        found: dict[str, tuple[str, int, int]] = {}
        while time.monotonic() < deadline and len(found) < len(topics):
            for topic in topics:
                infos = node.get_publishers_info_by_topic(topic)
                if infos:
                    q = infos[0].qos_profile
                    found[topic] = (str(infos[0].topic_type_hash), int(q.reliability), int(q.durability))
            time.sleep(0.05)
        node.destroy_node()
        return found
    finally:
        rclpy.shutdown(context=context)


# Tests --------------------------------------------------------------------------------------------------


def test_records_everything_with_qos_hashes_and_latched_config(procs: Processes, tmp_path: Path) -> None:
    ticks = 1500
    publisher = start_publisher(procs, ticks, rate=1000.0)
    offered = graph_publishers([*RELIABLE_TOPICS, "/clock", CONFIG_TOPIC])
    started_ns = time.time_ns()
    recorder = start_recorder(procs, tmp_path / "bags")  # joins late: the config was published before
    published = published_counts(procs, publisher)["published"]
    stop(procs, recorder)
    bag = the_run(tmp_path / "bags")
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    topics = {t["topic_metadata"]["name"]: t for t in info["topics_with_message_count"]}
    recorded = recorded_by_topic(bag)
    expected = expected_by_topic(ticks)
    for topic in RELIABLE_TOPICS:
        assert topics[topic]["message_count"] == published[topic], topic
        assert recorded[topic] == expected[topic], topic  # identical messages, in order
    assert 0 < len(recorded["/clock"]) <= published["/clock"]  # best effort by contract
    assert recorded[CONFIG_TOPIC] == [String(data=json.dumps(CONFIG))]
    recorder_config = json.loads(recorded["/recorder/config"][0].data)
    assert recorder_config["run_id"] == bag.name and recorder_config["bag"] == str(bag)
    for topic, (type_hash, reliability, durability) in offered.items():
        meta = topics[topic]["topic_metadata"]
        assert meta["type_description_hash"] == type_hash, topic  # the publisher's own RIHS01 hash
        (profile,) = meta["offered_qos_profiles"]
        assert profile["reliability"] == {1: "reliable", 2: "best_effort"}[reliability], topic
        assert profile["durability"] == {1: "transient_local", 2: "volatile"}[durability], topic
    with BagReader(bag) as reader:
        assert started_ns < reader.start_ns <= reader.start_ns + reader.duration_ns < time.time_ns()


def test_fast_simulation_rate_loses_nothing(procs: Processes, tmp_path: Path) -> None:
    ticks = 20000
    publisher = start_publisher(procs, ticks, rate=5000.0)
    recorder = start_recorder(procs, tmp_path / "bags")
    result = published_counts(procs, publisher)
    stop(procs, recorder)
    bag = the_run(tmp_path / "bags")
    with BagReader(bag) as reader:
        counts = {name: t.message_count for name, t in reader.topics.items()}
    print(
        f"published at {result['ticks_per_s']:.0f} ticks/s; /clock recorded {counts['/clock']} of "
        f"{result['published']['/clock']}"
    )
    for topic in RELIABLE_TOPICS:
        assert counts[topic] == result["published"][topic], topic


def test_sigterm_finalizes_the_bag(procs: Processes, tmp_path: Path) -> None:
    ticks = 300
    publisher = start_publisher(procs, ticks)
    recorder = start_recorder(procs, tmp_path / "bags")
    published = published_counts(procs, publisher)["published"]
    stop(procs, recorder, signal.SIGTERM)
    bag = the_run(tmp_path / "bags")
    assert (bag / "metadata.yaml").is_file()
    recorded = recorded_by_topic(bag)
    assert {t: len(recorded[t]) for t in RIG_TOPICS} == {t: published[t] for t in RIG_TOPICS}


def test_kill_9_then_recover_bag_keeps_every_flushed_chunk(procs: Processes, tmp_path: Path) -> None:
    ticks = 2000
    publisher = start_publisher(procs, ticks, rate=1000.0)
    recorder = start_recorder(procs, tmp_path / "bags", "chunk_period_s:=0.2")
    published_counts(procs, publisher)
    bag = the_run(tmp_path / "bags")
    deadline = time.monotonic() + 60  # every message is in a finished chunk within a chunk period
    while time.monotonic() < deadline:
        counts = recoverable_counts(bag)
        if all(counts.get(t) == ticks for t in RIG_TOPICS):
            break
        time.sleep(0.1)
    recorder.send_signal(signal.SIGKILL)
    recorder.wait(timeout=10)
    assert not (bag / "metadata.yaml").exists()
    done = subprocess.run(
        [str(console_script("g2p-recover-bag")), str(bag)], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    recorded = recorded_by_topic(bag)
    expected = expected_by_topic(ticks)
    for topic in RELIABLE_TOPICS:
        assert recorded[topic] == expected[topic], topic


def test_kill_9_mid_stream_recovers_a_clean_prefix(procs: Processes, tmp_path: Path) -> None:
    ticks = 30000
    publisher = start_publisher(procs, ticks, rate=5000.0)
    recorder = start_recorder(procs, tmp_path / "bags", "chunk_period_s:=1000.0")
    bag = the_run(tmp_path / "bags")
    deadline = time.monotonic() + 60
    seen: dict[str, int] = {}
    while time.monotonic() < deadline and seen.get("/leg/treadmill", 0) < 5000:
        time.sleep(0.05)
        seen = recoverable_counts(bag)
    assert publisher.poll() is None, "the publisher finished before the kill: make it publish longer"
    recorder.send_signal(signal.SIGKILL)  # while messages keep arriving
    recorder.wait(timeout=10)
    publisher.kill()
    publisher.wait(timeout=10)
    assert (
        subprocess.run(
            [str(console_script("g2p-recover-bag")), str(bag)], capture_output=True, timeout=120
        ).returncode
        == 0
    )
    recorded = recorded_by_topic(bag)
    expected = expected_by_topic(ticks)
    for topic in RIG_TOPICS:
        n = len(recorded[topic])
        assert n >= seen[topic], topic  # everything in a finished chunk before the kill is back
        assert recorded[topic] == expected[topic][:n], (
            topic
        )  # in order, nothing damaged or missing in between


def test_selection_regex_and_sim_time_stamps(procs: Processes, tmp_path: Path) -> None:
    ticks = 400
    included = ["/leg/joint_states", "/leg/treadmill", "/leg/applied_activation"]
    publisher = start_publisher(procs, ticks, rate=400.0, wait_for=included)
    recorder = start_recorder(
        procs,
        tmp_path / "bags",
        "include_regex:=^/(leg|clock)",
        "exclude_regex:=motor_power|/learner/",
        "use_sim_time:=true",
    )
    published_counts(procs, publisher)
    stop(procs, recorder)
    bag = the_run(tmp_path / "bags")
    with BagReader(bag) as reader:
        assert set(reader.topics) == {
            "/clock",
            "/leg/joint_states",
            "/leg/treadmill",
            "/leg/applied_activation",
            CONFIG_TOPIC,
        }
        stamps = [m.timestamp_ns for m in reader.raw_messages(["/leg/treadmill"])]
    # the recorder's clock follows /clock: every message is stamped with (about) the rig time of its tick
    assert STAMP0_NS <= min(stamps) and max(stamps) <= STAMP0_NS + ticks * TICK_NS
    assert stamps == sorted(stamps)
