"""Small known-answer tests: QoS adaptation, topic selection, run ids, replay planning, recorder config."""

from __future__ import annotations

from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import pytest

from g2p.bags import BagWriteError, TypeRegistry, create_run_bag, read_metadata
from g2p.bags.config import RecorderConfig
from g2p.bags.metadata import TopicInfo
from g2p.bags.qos import INFINITE, EndpointQos, duration_qos_time, make_qos, recording_qos, replay_qos
from g2p.bags.replay_plan import ReplayOptions, Timeline, parse_remap, plan_topics
from g2p.bags.runs import is_run_id, new_run_id
from g2p.bags.selection import TopicSelection, is_hidden
from g2p.validation import ConfigError
from tests.bags.bagdata import CLOCK_QOS, INFINITE_NS, LATCHED_QOS, SAMPLE_QOS

UNKNOWN_HISTORY = make_qos(
    3, 0, 1, 2, INFINITE_NS, INFINITE_NS, 1, INFINITE_NS, False
)  # as discovery reports it


def test_recording_qos_like_rosbag2() -> None:
    assert recording_qos([SAMPLE_QOS, SAMPLE_QOS], 500) == EndpointQos(True, False, False, 500)
    assert recording_qos([SAMPLE_QOS, CLOCK_QOS], 500).reliable is False  # one best-effort publisher
    assert recording_qos([LATCHED_QOS], 5).transient_local is True
    assert recording_qos([LATCHED_QOS, SAMPLE_QOS], 5).transient_local is False
    with pytest.raises(ValueError):
        recording_qos([], 5)


def test_replay_qos_uses_recorded_history_when_known() -> None:
    assert replay_qos([SAMPLE_QOS], 1000) == EndpointQos(True, False, False, 200)
    assert replay_qos([UNKNOWN_HISTORY], 1000) == EndpointQos(True, False, False, 1000)
    assert replay_qos([CLOCK_QOS], 1000) == EndpointQos(False, False, False, 1)
    assert replay_qos([LATCHED_QOS], 1000).transient_local is True
    assert replay_qos([], 10) == EndpointQos(True, False, False, 10)


def test_durations() -> None:
    assert duration_qos_time(INFINITE_NS) == INFINITE
    assert duration_qos_time(1_500_000_000) == (1, 500_000_000)
    assert make_qos(99, 1, 99, 99, 0, 0, 99, 0, False).history.name == "UNKNOWN"


@pytest.mark.parametrize(
    "topic, hidden",
    [("/leg/joint_states", False), ("/leg/run/_action/status", True), ("/_hidden", True), ("/a_b/c_", False)],
)
def test_hidden(topic: str, hidden: bool) -> None:
    assert is_hidden(topic) is hidden


def test_selection() -> None:
    everything = TopicSelection()
    assert everything.matches("/leg/joint_states") and not everything.matches("/leg/x/_action/feedback")
    assert TopicSelection(include_hidden=True).matches("/leg/x/_action/feedback")
    rig = TopicSelection(include="^/leg/", exclude="activation_cmd$")
    assert (
        rig.matches("/leg/treadmill") and not rig.matches("/leg/activation_cmd") and not rig.matches("/clock")
    )
    assert not TopicSelection(include="").matches("/clock")
    with pytest.raises(ValueError, match="include is not a regular expression"):
        TopicSelection(include="(")


def test_run_ids_sort_by_time_and_differ() -> None:
    rng = np.random.default_rng(0)
    t = datetime(2026, 11, 21, 12, 0, 0, tzinfo=timezone.utc)
    ids = [new_run_id(t + timedelta(seconds=s), rng) for s in (0, 0, 1, 60, 3600)]
    assert ids[0].startswith("20261121T120000Z-") and all(is_run_id(i) for i in ids)
    assert len(set(ids)) == len(ids)
    assert sorted(ids[1:]) == ids[1:] and ids[0][:16] == ids[1][:16]
    local = datetime(2026, 11, 21, 13, 0, 0, tzinfo=timezone(timedelta(hours=1)))
    assert new_run_id(local, rng).startswith("20261121T120000Z-")
    with pytest.raises(ValueError):
        new_run_id(datetime(2026, 1, 1), rng)


def test_create_run_bag_skips_existing_ids(tmp_path: Path) -> None:
    t = datetime(2026, 11, 21, 12, 0, 0, tzinfo=timezone.utc)
    taken = new_run_id(t, np.random.default_rng(5))
    (tmp_path / taken).mkdir()
    writer = create_run_bag(tmp_path, t, np.random.default_rng(5))
    writer.close()
    assert writer.path.name != taken and writer.path.name.startswith("20261121T120000Z-")
    assert read_metadata(writer.path).custom_data == {"g2p.run_id": writer.path.name}
    with pytest.raises(BagWriteError, match="run directory exists already"):
        create_run_bag(tmp_path, t, np.random.default_rng(5), run_id=taken)


def test_writer_rejects_use_after_close(tmp_path: Path, registry: TypeRegistry) -> None:
    from g2p.bags import BagWriter, TopicSpec

    writer = BagWriter(tmp_path / "b")
    handle = writer.add_topic(TopicSpec("/t", registry.definition("std_msgs/msg/String")))
    writer.close()
    writer.close()  # idempotent
    with pytest.raises(BagWriteError):
        writer.write(handle, 1, b"\x00\x01\x00\x00\x01\x00\x00\x00\x00")
    with pytest.raises(BagWriteError, match="exists already"):
        BagWriter(tmp_path / "b")


TOPICS = {
    "/clock": TopicInfo("/clock", "rosgraph_msgs/msg/Clock", "cdr", (CLOCK_QOS,), "", 10),
    "/leg/joint_states": TopicInfo(
        "/leg/joint_states", "sensor_msgs/msg/JointState", "cdr", (SAMPLE_QOS,), "", 10
    ),
    "/leg/treadmill": TopicInfo(
        "/leg/treadmill", "g2p_interfaces/msg/Treadmill", "cdr", (UNKNOWN_HISTORY,), "", 10
    ),
}


def test_plan_all_topics() -> None:
    plan = plan_topics(TOPICS, ReplayOptions())
    assert [(t.source, t.output) for t in plan] == [(n, n) for n in sorted(TOPICS)]
    assert plan[1].qos == EndpointQos(True, False, False, 200)
    assert plan[2].qos.depth == 1000


def test_plan_selection_remap_and_clock() -> None:
    options = ReplayOptions(
        topics=("/leg/treadmill", "/clock"), remaps=(("/leg/treadmill", "/replay/treadmill"),), clock_hz=100.0
    )
    plan = plan_topics(TOPICS, options)
    assert [(t.source, t.output) for t in plan] == [
        ("/leg/treadmill", "/replay/treadmill")
    ]  # --clock replaces /clock


@pytest.mark.parametrize(
    "options, match",
    [
        (ReplayOptions(topics=("/nope",)), "not in the bag: /nope"),
        (
            ReplayOptions(remaps=(("/clock", "/leg/treadmill"),)),
            "several topics would be published on /leg/treadmill",
        ),
        (
            ReplayOptions(remaps=(("/leg/treadmill", "/clock"),), clock_hz=10.0),
            "/clock is published by --clock",
        ),
    ],
)
def test_plan_errors(options: ReplayOptions, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        plan_topics(TOPICS, options)


def test_options_and_remap_parsing() -> None:
    assert parse_remap("/a:=/b") == ("/a", "/b")
    for bad in ("/a=/b", ":=/b", "/a:="):
        with pytest.raises(ConfigError):
            parse_remap(bad)
    for kwargs in (
        {"rate": 0.0},
        {"rate": float("nan")},
        {"clock_hz": -1.0},
        {"remaps": (("a", "/b"),)},
        {"remaps": (("/a", "/b"), ("/a", "/c"))},
        {"default_depth": 0},
    ):
        with pytest.raises(ConfigError):
            ReplayOptions(**kwargs)  # type: ignore[arg-type]


def test_timeline() -> None:
    timeline = Timeline(bag_start_ns=10_000_000_000, wall_start_s=100.0, rate=2.0)
    assert timeline.due_s(10_000_000_000) == 100.0
    assert timeline.due_s(12_000_000_000) == pytest.approx(101.0)
    assert timeline.bag_time_ns(101.0) == 12_000_000_000
    with pytest.raises(ConfigError):
        Timeline(0, 0.0, 0.0)


def test_recorder_config_validation() -> None:
    assert RecorderConfig().selection() == TopicSelection(".*", "", False)
    for kwargs in (
        {"include_regex": "("},
        {"run_id": "../x"},
        {"run_id": ".hidden"},
        {"queue_depth": 0},
        {"chunk_period_s": 0.0},
        {"discovery_period_s": float("inf")},
        {"bags_dir": ""},
    ):
        with pytest.raises(ConfigError):
            RecorderConfig(**kwargs)  # type: ignore[arg-type]
    assert RecorderConfig(run_id="demo-1").run_id == "demo-1"
