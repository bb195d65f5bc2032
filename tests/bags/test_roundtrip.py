"""Round trip: a bag written by g2p.bags is read back identically by two independent readers.

rosbags' AnyReader and the mcap library's ROS 2 reader (mcap_ros2) each decode every message from the
schemas embedded in the bag; both must give back exactly the written values, in order. metadata.yaml
must carry every field rosbag2 version 9 requires, consistent with the messages written.
"""

from __future__ import annotations

import dataclasses
import json
import math
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from g2p.bags import BagReader, BagWriter, TopicSpec, TypeRegistry, read_metadata
from g2p.bags.metadata import REQUIRED_KEYS, REQUIRED_TOPIC_KEYS
from g2p.bags.qos import INFINITE

with warnings.catch_warnings():  # mcap_ros2.reader imports a deprecated mcap_ros1 module
    warnings.simplefilter("ignore", DeprecationWarning)
    from mcap_ros2.reader import read_ros2_messages

from tests.bags.bagdata import CLOCK_QOS, LATCHED_QOS, SAMPLE_QOS, Messages


def canon(value: Any) -> Any:
    """A message as plain nested lists/tuples, whatever reader made it (NaN compares equal to NaN)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return tuple(
            (f.name, canon(getattr(value, f.name)))
            for f in dataclasses.fields(value)
            if not f.name.startswith("__") and not f.name.isupper()
        )
    if hasattr(value, "__slots__") and not isinstance(value, (str, bytes)):
        # ROS 2 field names are lower case; upper-case slots are constants (mcap_ros2 lists them too)
        return tuple((name, canon(getattr(value, name))) for name in value.__slots__ if not name.isupper())
    if isinstance(value, (np.ndarray, list, tuple, bytes, bytearray)):
        return [canon(v) for v in (value.tolist() if isinstance(value, np.ndarray) else value)]
    if isinstance(value, (np.floating, float)):
        return "nan" if math.isnan(value) else float(value)
    if isinstance(value, np.integer):
        return int(value)
    return value


def build_messages(messages: Messages, n: int) -> list[tuple[str, int, Any]]:
    """(topic, timestamp ns, message) of every type the recorder writes, with varied content."""
    rng = np.random.default_rng(7)
    out: list[tuple[str, int, Any]] = []
    for k in range(n):
        t = 5_000_000_000 + k * 12_820_513
        h = messages.header(t)
        out += [
            ("/clock", t, messages.make("rosgraph_msgs/msg/Clock", clock=messages.time(t))),
            (
                "/leg/joint_states",
                t + 1,
                messages.make(
                    "sensor_msgs/msg/JointState",
                    header=h,
                    name=["proximal", "distal"],
                    position=rng.normal(size=2),
                    velocity=rng.normal(size=2),
                    effort=np.zeros(0),
                ),
            ),
            (
                "/leg/treadmill",
                t + 2,
                messages.make(
                    "g2p_interfaces/msg/Treadmill",
                    header=h,
                    displacement_mm=float(rng.normal()),
                    velocity_mm_s=-1.5,
                ),
            ),
            (
                "/leg/motor_power",
                t + 3,
                messages.make(
                    "g2p_interfaces/msg/MotorPower",
                    header=h,
                    current_a=rng.uniform(0, 2, 3),
                    power_w=rng.normal(size=3),
                    energy_j=rng.uniform(0, 9, 3),
                ),
            ),
            (
                "/leg/applied_activation",
                t + 4,
                messages.make(
                    "g2p_interfaces/msg/MotorActivation", header=h, activation=rng.uniform(0.15, 1, 3)
                ),
            ),
        ]
        if k % 50 == 0:
            out.append(
                (
                    "/leg/learner/events",
                    t + 5,
                    messages.make(
                        "g2p_interfaces/msg/LearnerEvent",
                        header=h,
                        run_id="r",
                        event="attempt_end",
                        phase="exploration",
                        attempt=k // 50 + 1,
                        features=rng.uniform(0.15, 1, 10),
                        reward_mm=float(k),
                        energy_j=float("nan"),
                        tracking_mse_deg2=1.0,
                        tracking_rmse_rad=0.5,
                        best_reward_mm=2.0,
                        sigma=0.03,
                        detail=json.dumps({"k": k, "text": "ünïcode"}),
                    ),
                )
            )
            out.append(
                (
                    "/leg/learner/inverse_map",
                    t + 6,
                    messages.make(
                        "g2p_interfaces/msg/InverseMapWeights",
                        header=h,
                        run_id="r",
                        refinement=k // 50,
                        format_version=1,
                        arrays=[
                            messages.make(
                                "g2p_interfaces/msg/NamedArray",
                                name="W1",
                                shape=np.array([3, 2], np.uint32),
                                data=rng.normal(size=6),
                            )
                        ],
                        training_samples=k,
                        validation_rmse=0.25,
                    ),
                )
            )
            out.append(
                (
                    "/diagnostics",
                    t + 7,
                    messages.make(
                        "diagnostic_msgs/msg/DiagnosticArray",
                        header=h,
                        status=[
                            messages.make(
                                "diagnostic_msgs/msg/DiagnosticStatus",
                                level=b"\x01"[0],
                                name="rig",
                                message="ok",
                                hardware_id="sim",
                                values=[
                                    messages.make("diagnostic_msgs/msg/KeyValue", key="ticks", value=str(k))
                                ],
                            )
                        ],
                    ),
                )
            )
    out.append(("/leg/learner/config", 4_000_000_000, messages.make("std_msgs/msg/String", data='{"a": 1}')))
    return out


TYPES = {
    "/clock": ("rosgraph_msgs/msg/Clock", CLOCK_QOS),
    "/leg/joint_states": ("sensor_msgs/msg/JointState", SAMPLE_QOS),
    "/leg/treadmill": ("g2p_interfaces/msg/Treadmill", SAMPLE_QOS),
    "/leg/motor_power": ("g2p_interfaces/msg/MotorPower", SAMPLE_QOS),
    "/leg/applied_activation": ("g2p_interfaces/msg/MotorActivation", SAMPLE_QOS),
    "/leg/learner/events": ("g2p_interfaces/msg/LearnerEvent", SAMPLE_QOS),
    "/leg/learner/inverse_map": ("g2p_interfaces/msg/InverseMapWeights", LATCHED_QOS),
    "/leg/learner/config": ("std_msgs/msg/String", LATCHED_QOS),
    "/diagnostics": ("diagnostic_msgs/msg/DiagnosticArray", SAMPLE_QOS),
}


@pytest.fixture(scope="module")
def written(
    tmp_path_factory: pytest.TempPathFactory, registry: TypeRegistry, messages: Messages
) -> tuple[Path, list[tuple[str, int, Any]]]:
    path = tmp_path_factory.mktemp("bags") / "roundtrip"
    msgs = build_messages(messages, 3000)  # > 1 MiB: several zstd chunks
    with BagWriter(path, {"g2p.run_id": "roundtrip"}) as writer:
        handles = {
            topic: writer.add_topic(TopicSpec(topic, registry.definition(t), (q,)))
            for topic, (t, q) in TYPES.items()
        }
        for topic, t, msg in msgs:
            writer.write(handles[topic], t, messages.cdr(msg))
    return path, msgs


def expected_in_time_order(msgs: list[tuple[str, int, Any]]) -> list[tuple[str, int, Any]]:
    return [(topic, t, canon(m)) for topic, t, m in sorted(msgs, key=lambda x: x[1])]


def test_rosbags_anyreader_reads_every_message(written: tuple[Path, list[tuple[str, int, Any]]]) -> None:
    path, msgs = written
    with AnyReader([path]) as reader:
        got = [(c.topic, t, canon(reader.deserialize(raw, c.msgtype))) for c, t, raw in reader.messages()]
    assert got == expected_in_time_order(msgs)


def test_mcap_ros2_reader_reads_every_message(written: tuple[Path, list[tuple[str, int, Any]]]) -> None:
    path, msgs = written
    got = [
        (m.channel.topic, m.log_time_ns, canon(m.ros_msg))
        for m in read_ros2_messages(str(path / f"{path.name}.mcap"), log_time_order=True)
    ]
    assert got == expected_in_time_order(msgs)


def test_bag_reader_decodes_and_keeps_raw_bytes(
    written: tuple[Path, list[tuple[str, int, Any]]], messages: Messages
) -> None:
    path, msgs = written
    with BagReader(path) as reader:
        raw = [(m.topic, m.timestamp_ns, m.data) for m in reader.raw_messages()]
        decoded = [(m.topic, m.timestamp_ns, canon(m.msg)) for m in reader.messages(["/leg/treadmill"])]
    ordered = sorted(msgs, key=lambda x: x[1])
    assert raw == [(topic, t, messages.cdr(m)) for topic, t, m in ordered]
    assert decoded == [x for x in expected_in_time_order(msgs) if x[0] == "/leg/treadmill"]


def test_metadata_has_every_v9_field_and_is_consistent(
    written: tuple[Path, list[tuple[str, int, Any]]], registry: TypeRegistry
) -> None:
    path, msgs = written
    info = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert set(REQUIRED_KEYS) <= set(info)
    assert info["version"] == 9
    assert info["storage_identifier"] == "mcap"
    assert info["relative_file_paths"] == ["roundtrip.mcap"]
    assert (path / "roundtrip.mcap").is_file()
    times = [t for _, t, _ in msgs]
    assert info["message_count"] == len(msgs)
    assert info["starting_time"]["nanoseconds_since_epoch"] == min(times)
    assert info["duration"]["nanoseconds"] == max(times) - min(times)
    assert info["files"] == [
        {
            "path": "roundtrip.mcap",
            "message_count": len(msgs),
            "starting_time": {"nanoseconds_since_epoch": min(times)},
            "duration": {"nanoseconds": max(times) - min(times)},
        }
    ]
    assert (
        info["compression_format"] == "" and info["compression_mode"] == ""
    )  # chunk compression is inside MCAP
    assert info["custom_data"] == {"g2p.run_id": "roundtrip"}
    assert isinstance(info["ros_distro"], str) and info["ros_distro"]
    topics = {t["topic_metadata"]["name"]: t for t in info["topics_with_message_count"]}
    assert set(topics) == set(TYPES)
    for name, (msgtype, qos) in TYPES.items():
        meta = topics[name]["topic_metadata"]
        assert set(REQUIRED_TOPIC_KEYS) <= set(meta)
        assert topics[name]["message_count"] == sum(topic == name for topic, _, _ in msgs)
        assert meta["type"] == msgtype
        assert meta["serialization_format"] == "cdr"
        assert meta["type_description_hash"] == registry.definition(msgtype).rihs01
        (profile,) = meta["offered_qos_profiles"]  # version 9: a YAML list, not a string
        assert profile["history"] == "keep_last" and profile["depth"] == qos.depth
        assert profile["reliability"] == qos.reliability.name.lower()
        assert profile["durability"] == qos.durability.name.lower()
        assert profile["deadline"] == {"sec": INFINITE.sec, "nsec": INFINITE.nsec}
    parsed = read_metadata(path)
    assert {n: t.offered_qos for n, t in parsed.topics.items()} == {n: (q,) for n, (_, q) in TYPES.items()}


def test_mcap_has_zstd_chunks_schemas_and_channel_metadata(
    written: tuple[Path, list[tuple[str, int, Any]]], registry: TypeRegistry
) -> None:
    path, msgs = written
    with open(path / f"{path.name}.mcap", "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        header = reader.get_header()
        assert summary is not None
        assert header.profile == "ros2"
        assert len(summary.chunk_indexes) > 1
        assert {c.compression for c in summary.chunk_indexes} == {"zstd"}
        assert (
            sum(c.compressed_size for c in summary.chunk_indexes)
            < sum(c.uncompressed_size for c in summary.chunk_indexes) / 2
        )
        assert summary.statistics.message_count == len(msgs)
        channels = {c.topic: c for c in summary.channels.values()}
        for name, (msgtype, _) in TYPES.items():
            channel = channels[name]
            schema = summary.schemas[channel.schema_id]
            assert (schema.name, schema.encoding) == (msgtype, "ros2msg")
            assert schema.data.decode() == registry.definition(msgtype).msgdef
            assert channel.message_encoding == "cdr"
            assert channel.metadata["topic_type_hash"] == registry.definition(msgtype).rihs01
            assert yaml.safe_load(channel.metadata["offered_qos_profiles"])[0]["history"] == "keep_last"
        rosbag2_metadata = [m for m in reader.iter_metadata() if m.name == "rosbag2"]
        assert yaml.safe_load(rosbag2_metadata[0].metadata["serialized_metadata"])["version"] == 9
