"""The rig's serialized tick messages read back (rclpy, rosbags) as the messages of `tick_messages`."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from rclpy.serialization import deserialize_message
from std_msgs.msg import Header

from g2p.bags.interfaces import InterfaceLibrary, TypeRegistry, ament_share_dirs
from g2p.plant import TickSample, stamp_ns
from g2p_ros.convert import tick_messages, tick_sample, time_from_ns
from g2p_ros.tick_serializer import TickSerializer


def _sample(rng: np.random.Generator, t_s: float) -> TickSample:
    return TickSample(
        t_s=t_s,
        activation=rng.uniform(0.15, 1.0, 3),
        position_rad=rng.normal(size=2),
        velocity_rad_s=rng.normal(scale=5.0, size=2),
        belt_mm=float(rng.normal(scale=1e3)),
        belt_velocity_mm_s=float(rng.normal(scale=100.0)),
        current_a=rng.uniform(0.0, 2.0, 3),
        power_w=rng.normal(size=3),
        energy_j=rng.uniform(0.0, 1e4, 3),
    )


# Simulation time from 0, and system time (the hardware driver's stamps) near the end of a second.
@pytest.mark.parametrize("t_s", [0.0, 12.820513, 1_795_000_000.999999999])
def test_deserializes_to_the_messages(t_s: float) -> None:
    serializer = TickSerializer()
    types = TypeRegistry(InterfaceLibrary(ament_share_dirs()))
    rng = np.random.default_rng(7)
    for _ in range(20):
        sample = _sample(rng, t_s)
        ns = stamp_ns(t_s)
        got = serializer.serialize(sample, ns)
        want = tick_messages(sample, time_from_ns(ns))
        assert [deserialize_message(data, type(msg)) for data, msg in zip(got, want, strict=True)] == list(
            want
        )
        for data, msg in zip(
            got, want, strict=True
        ):  # rosbags checks the length too, as the report's bag reader does
            name = f"{type(msg).__module__.split('.')[0]}/msg/{type(msg).__name__}"
            types.register(name)
            decoded = types.typestore.deserialize_cdr(data, name)
            assert (decoded.header.stamp.sec, decoded.header.stamp.nanosec) == divmod(ns, 1_000_000_000)


def test_every_value_lands_in_its_field() -> None:
    """Distinct values in every field: a swapped or missing offset shows as a wrong field."""
    values = iter(np.arange(1.0, 100.0))
    sample = TickSample(
        t_s=1.0,
        activation=np.array([next(values) for _ in range(3)]),
        position_rad=np.array([next(values) for _ in range(2)]),
        velocity_rad_s=np.array([next(values) for _ in range(2)]),
        belt_mm=next(values),
        belt_velocity_mm_s=next(values),
        current_a=np.array([next(values) for _ in range(3)]),
        power_w=np.array([next(values) for _ in range(3)]),
        energy_j=np.array([next(values) for _ in range(3)]),
    )
    serialized = TickSerializer().serialize(sample, 1_500_000_000)
    messages = tick_messages(sample, time_from_ns(0))
    joints, treadmill, power, applied = (
        deserialize_message(data, type(msg)) for data, msg in zip(serialized, messages, strict=True)
    )
    assert list(applied.activation) == [1.0, 2.0, 3.0]
    assert list(joints.position) == [4.0, 5.0] and list(joints.velocity) == [6.0, 7.0]
    assert (treadmill.displacement_mm, treadmill.velocity_mm_s) == (8.0, 9.0)
    assert list(power.current_a) == [10.0, 11.0, 12.0]
    assert list(power.power_w) == [13.0, 14.0, 15.0]
    assert list(power.energy_j) == [16.0, 17.0, 18.0]
    for msg in (joints, treadmill, power, applied):
        assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1, 500_000_000)
        assert msg.header.frame_id == "leg"


@pytest.mark.parametrize("t_s", [0.0, 12.820513, 1_795_000_000.999999999])
def test_tick_sample_reads_back_the_published_messages(t_s: float) -> None:
    """What TickPlant reads off the rig topics is the sample the rig published, bit for bit."""
    serializer = TickSerializer()
    sample = _sample(np.random.default_rng(3), t_s)
    ns = stamp_ns(t_s)
    messages = [
        deserialize_message(data, type(msg))
        for data, msg in zip(
            serializer.serialize(sample, ns), tick_messages(sample, time_from_ns(0)), strict=True
        )
    ]
    back = tick_sample(*messages)
    assert back.t_s == ns * 1e-9
    for field in dataclasses.fields(TickSample):
        if field.name != "t_s":
            np.testing.assert_array_equal(getattr(back, field.name), getattr(sample, field.name), field.name)


def test_tick_sample_refuses_messages_of_different_ticks() -> None:
    sample = _sample(np.random.default_rng(4), 1.0)
    joints, treadmill, power, applied = tick_messages(sample, time_from_ns(1_000_000_000))
    # A header of its own: tick_messages gives the four messages one Header object.
    treadmill.header = Header(stamp=time_from_ns(1_012_820_513), frame_id="leg")
    with pytest.raises(ValueError, match="share one stamp"):
        tick_sample(joints, treadmill, power, applied)
    joints, treadmill, power, applied = tick_messages(sample, time_from_ns(1_000_000_000))
    joints.name = ["distal", "proximal"]
    with pytest.raises(ValueError, match=r"JointState\.name"):
        tick_sample(joints, treadmill, power, applied)
