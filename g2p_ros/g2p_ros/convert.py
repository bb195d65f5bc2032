"""Conversion between the rig contract's messages and the core's types, in one place.

Tick samples and recordings (the rig topics, RigSamples), inverse maps (InverseMapWeights' arrays, the
g2p.inverse_map format) and closed-loop trajectories (RunTrajectory goals).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Mapping, Sequence
from dataclasses import fields
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from g2p.bags.interfaces import InterfaceLibrary, TypeRegistry, ament_share_dirs
from g2p.closed_loop import FeedbackConfig, Trajectory
from g2p.inverse_map import N_INPUTS, InverseMap, InverseMapFormatError
from g2p.plant import JOINT_NAMES, N_JOINTS, N_MOTORS, Recording, TickSample
from g2p_interfaces.action import RunTrajectory
from g2p_interfaces.msg import (
    InverseMapWeights,
    MotorActivation,
    MotorPower,
    NamedArray,
    RigSamples,
    Treadmill,
)

FRAME_ID = "leg"


def time_from_ns(ns: int) -> Time:
    """A builtin_interfaces/Time from integer nanoseconds."""
    sec, nanosec = divmod(ns, 1_000_000_000)
    return Time(sec=sec, nanosec=nanosec)


def tick_messages(
    sample: TickSample, stamp: Time
) -> tuple[JointState, Treadmill, MotorPower, MotorActivation]:
    """The four messages the rig publishes for one tick, sharing one header stamp."""
    header = Header(stamp=stamp, frame_id=FRAME_ID)
    joints = JointState(
        header=header,
        name=list(JOINT_NAMES),
        position=sample.position_rad.tolist(),
        velocity=sample.velocity_rad_s.tolist(),
    )
    treadmill = Treadmill(
        header=header, displacement_mm=float(sample.belt_mm), velocity_mm_s=float(sample.belt_velocity_mm_s)
    )
    power = MotorPower(
        header=header,
        current_a=sample.current_a.tolist(),
        power_w=sample.power_w.tolist(),
        energy_j=sample.energy_j.tolist(),
    )
    applied = MotorActivation(header=header, activation=sample.activation.tolist())
    return joints, treadmill, power, applied


def tick_sample(
    joints: JointState, treadmill: Treadmill, power: MotorPower, applied: MotorActivation
) -> TickSample:
    """The sample of one tick from its four messages (the inverse of `tick_messages`).

    `t_s` is the shared header stamp in seconds, as `recording_from_msg` gives it (stamp ns * 1e-9);
    `activation` is the applied activation.

    Raises:
        ValueError: the stamps differ, the joints are not named `JOINT_NAMES` in order, or a field has the
            wrong number of values.
    """
    stamps = {(m.header.stamp.sec, m.header.stamp.nanosec) for m in (joints, treadmill, power, applied)}
    if len(stamps) != 1:
        raise ValueError(f"a tick's four messages must share one stamp, got {sorted(stamps)}")
    if tuple(joints.name) != JOINT_NAMES:
        raise ValueError(f"JointState.name: expected {list(JOINT_NAMES)}, got {list(joints.name)}")
    ((sec, nanosec),) = stamps

    def values(v: object, n: int, name: str) -> np.ndarray:
        a = np.asarray(v, dtype=np.float64)
        if a.shape != (n,):
            raise ValueError(f"{name}: expected {n} values, got {a.size}")
        return a

    return TickSample(
        t_s=(sec * 1_000_000_000 + nanosec) * 1e-9,
        activation=values(applied.activation, N_MOTORS, "MotorActivation.activation"),
        position_rad=values(joints.position, N_JOINTS, "JointState.position"),
        velocity_rad_s=values(joints.velocity, N_JOINTS, "JointState.velocity"),
        belt_mm=float(treadmill.displacement_mm),
        belt_velocity_mm_s=float(treadmill.velocity_mm_s),
        current_a=values(power.current_a, N_MOTORS, "MotorPower.current_a"),
        power_w=values(power.power_w, N_MOTORS, "MotorPower.power_w"),
        energy_j=values(power.energy_j, N_MOTORS, "MotorPower.energy_j"),
    )


# TickSample's numeric fields, in the order TickSerializer takes their values.
_TICK_FIELDS = tuple(f.name for f in fields(TickSample) if f.name != "t_s")
# Stamp sentinels (int32 sec, uint32 nanosec) for the templates; their bytes appear nowhere else.
_SENTINEL_SEC, _SENTINEL_NANOSEC = 0x5A5A5A01, 0x5A5A5A02
_STAMP = struct.Struct("<iI")
_FLOAT64 = struct.Struct("<d")


class TickSerializer:
    """The four messages of `tick_messages`, serialized (CDR), without building rclpy message objects.

    Building the four messages costs about 40 us per tick (rclpy's field setters check every value) with
    the GIL held, which in fast simulation limits the rig (docs/RESULTS.md). Every per-tick field has a
    fixed size (two joints, three motors, a constant frame_id), so each message's serialized form is a
    template with the tick's numbers at fixed offsets. The templates are `tick_messages` for a sample whose
    every number is a distinct sentinel, serialized by rclpy and normalized by rosbags (`_canonical`); each
    sentinel's position is where its value goes.

    Raises:
        ValueError: (at construction) a sentinel is not found exactly once, i.e. the layout is not fixed.
    """

    def __init__(self) -> None:
        sentinels = iter(float(k) * 1e300 for k in range(1, 100))

        def row(n: int) -> np.ndarray:
            return np.array([next(sentinels) for _ in range(n)])

        sample = TickSample(
            t_s=0.0,
            activation=row(N_MOTORS),
            position_rad=row(N_JOINTS),
            velocity_rad_s=row(N_JOINTS),
            belt_mm=next(sentinels),
            belt_velocity_mm_s=next(sentinels),
            current_a=row(N_MOTORS),
            power_w=row(N_MOTORS),
            energy_j=row(N_MOTORS),
        )
        flat = _flatten(sample)
        stamp = Time(sec=_SENTINEL_SEC, nanosec=_SENTINEL_NANOSEC)
        types = TypeRegistry(InterfaceLibrary(ament_share_dirs()))
        self._templates: list[tuple[bytes, int, list[tuple[int, int]]]] = []
        for msg in tick_messages(sample, stamp):
            data = _canonical(msg, types)
            if data[:2] != b"\x00\x01":  # CDR encapsulation: plain, little endian
                raise ValueError(f"{type(msg).__name__}: expected little-endian CDR, got {data[:2].hex()}")
            stamp_at = _find_once(data, _STAMP.pack(_SENTINEL_SEC, _SENTINEL_NANOSEC), type(msg).__name__)
            slots = [
                (i, at)
                for i, value in enumerate(flat)
                if (at := _find_once(data, _FLOAT64.pack(value), type(msg).__name__, required=False)) >= 0
            ]
            self._templates.append((data, stamp_at, slots))

    def serialize(self, sample: TickSample, stamp_ns: int) -> list[bytes]:
        """The serialized JointState, Treadmill, MotorPower and MotorActivation of one tick.

        Args:
            sample: the tick.
            stamp_ns: the header stamp (ns), as `stamp_ns` rounds it.
        """
        sec, nanosec = divmod(stamp_ns, 1_000_000_000)
        flat = _flatten(sample)
        out = []
        for data, stamp_at, slots in self._templates:
            buf = bytearray(data)
            _STAMP.pack_into(buf, stamp_at, sec, nanosec)
            for i, at in slots:
                _FLOAT64.pack_into(buf, at, flat[i])
            out.append(bytes(buf))
        return out


def _canonical(msg: Any, types: TypeRegistry) -> bytes:
    """`msg` serialized as DDS sends it and rosbags reads it: exact length, zero padding.

    rclpy's serialize_message returns rmw's estimated size, which may exceed the message (rosbags rejects
    the extra bytes), and leaves alignment padding uninitialized. The longest prefix rosbags accepts is the
    message; rosbags serializes it again with zero padding.
    """
    data = serialize_message(msg)
    name = f"{type(msg).__module__.split('.')[0]}/msg/{type(msg).__name__}"
    types.register(name)
    for end in range(len(data), 3, -1):
        out = types.reserialize(data[:end], name)
        if out is not None and deserialize_message(out, type(msg)) == msg:
            return out
    raise ValueError(f"{name}: rosbags does not read rclpy's serialization of the message")


def _flatten(sample: TickSample) -> list[float]:
    return np.hstack([getattr(sample, name) for name in _TICK_FIELDS]).tolist()


def _find_once(data: bytes, pattern: bytes, what: str, required: bool = True) -> int:
    at = data.find(pattern)
    if (at < 0 and required) or (at >= 0 and data.find(pattern, at + 1) >= 0):
        raise ValueError(f"{what}: a field's sentinel is not found exactly once: the layout is not fixed")
    return at


def stamp_ns(t_s: float) -> int:
    """Integer nanoseconds of a stamp in seconds (rounded to the nanosecond)."""
    return round(t_s * 1e9)


def rig_samples_msg(recording: Recording, stamps_ns: np.ndarray) -> RigSamples:
    """Pack a recording into RigSamples, with the ticks' header stamps (ns), shape (N,)."""
    return RigSamples(
        stamp_ns=np.asarray(stamps_ns, dtype=np.int64),
        applied_activation=recording.activation.ravel(),
        position_rad=recording.position_rad.ravel(),
        velocity_rad_s=recording.velocity_rad_s.ravel(),
        belt_displacement_mm=recording.belt_mm,
        belt_velocity_mm_s=recording.belt_velocity_mm_s,
        current_a=recording.current_a.ravel(),
        power_w=recording.power_w.ravel(),
        energy_j=recording.energy_j.ravel(),
    )


def recording_from_msg(msg: RigSamples) -> Recording:
    """Unpack RigSamples into a Recording; t_s is each tick's header stamp in seconds (stamp_ns * 1e-9).

    Raises:
        ValueError: the arrays' lengths disagree.
    """
    n = len(msg.stamp_ns)

    def rows(values: object, width: int, name: str) -> np.ndarray:
        a = np.asarray(values, dtype=np.float64)
        if a.size != n * width:
            raise ValueError(f"RigSamples.{name}: expected {n} x {width} values, got {a.size}")
        return a.reshape(n, width)

    return Recording(
        t_s=np.asarray(msg.stamp_ns, dtype=np.int64) * 1e-9,
        activation=rows(msg.applied_activation, N_MOTORS, "applied_activation"),
        position_rad=rows(msg.position_rad, N_JOINTS, "position_rad"),
        velocity_rad_s=rows(msg.velocity_rad_s, N_JOINTS, "velocity_rad_s"),
        belt_mm=rows(msg.belt_displacement_mm, 1, "belt_displacement_mm")[:, 0],
        belt_velocity_mm_s=rows(msg.belt_velocity_mm_s, 1, "belt_velocity_mm_s")[:, 0],
        current_a=rows(msg.current_a, N_MOTORS, "current_a"),
        power_w=rows(msg.power_w, N_MOTORS, "power_w"),
        energy_j=rows(msg.energy_j, N_MOTORS, "energy_j"),
    )


# Inverse maps -------------------------------------------------------------------------------------------


def map_weights_arrays(arrays: Mapping[str, np.ndarray]) -> list[NamedArray]:
    """InverseMapWeights.arrays from `InverseMap.to_arrays()`.

    Every named array but `format_version`, which the message carries in its own field
    (`int(arrays["format_version"][0])`).

    Args:
        arrays: name -> array, as `InverseMap.to_arrays()` returns them (not modified).
    """
    return [
        NamedArray(name=name, shape=list(np.shape(value)), data=np.asarray(value, dtype=np.float64).ravel())
        for name, value in arrays.items()
        if name != "format_version"
    ]


def map_from_weights(
    arrays: Sequence[NamedArray], format_version: int, source: str = "InverseMapWeights"
) -> InverseMap:
    """The inverse map of InverseMapWeights' `arrays` and `format_version` (numpy only: no torch).

    Args:
        arrays: the named arrays, row-major.
        format_version: the message's format version.
        source: what the arrays came from, for error messages.

    Raises:
        InverseMapFormatError: an array's data does not fit its shape, a name appears twice, or
            `InverseMap.from_arrays` refuses them (wrong version, names, shapes, non-finite values).
    """
    named: dict[str, np.ndarray] = {}
    for array in arrays:
        name = str(array.name)
        data = np.asarray(array.data, dtype=np.float64)
        shape = tuple(int(n) for n in array.shape)
        if math.prod(shape) != data.size:
            raise InverseMapFormatError(f"{source}: {name} has shape {list(shape)} but {data.size} values")
        if name in named:
            raise InverseMapFormatError(f"{source}: {name} appears twice")
        named[name] = data.reshape(shape)
    named["format_version"] = np.array([float(format_version)])
    return InverseMap.from_arrays(named, source=source)


def inverse_map_weights_msg(inverse_map: InverseMap) -> InverseMapWeights:
    """The map as InverseMapWeights (format_version and arrays; the run's fields left empty)."""
    arrays = inverse_map.to_arrays()
    return InverseMapWeights(
        format_version=int(arrays["format_version"][0]), arrays=map_weights_arrays(arrays)
    )


# Closed-loop trajectories ---------------------------------------------------------------------------------


def trajectory_goal(trajectory: Trajectory) -> RunTrajectory.Goal:
    """The run_trajectory goal that plays `trajectory`."""
    fb = trajectory.feedback
    return RunTrajectory.Goal(
        desired=np.asarray(trajectory.desired, dtype=np.float64).ravel(),
        inverse_map=inverse_map_weights_msg(trajectory.inverse_map),
        p_gain_per_s=np.asarray(fb.p_gain_per_s, dtype=np.float64),
        i_gain_per_s2=np.asarray(fb.i_gain_per_s2, dtype=np.float64),
        velocity_gain=np.asarray(fb.velocity_gain, dtype=np.float64),
        integral_limit_rad_s=float(fb.integral_limit_rad_s),
        correction_limit_rad_s=float(fb.correction_limit_rad_s),
        delay_ticks=int(fb.delay_ticks),
        lead_ticks=int(trajectory.lead_ticks),
    )


def trajectory_from_goal(goal: RunTrajectory.Goal) -> Trajectory:
    """The trajectory a run_trajectory goal asks for, validated as the rig plays it.

    Raises:
        ValueError: the desired kinematics are not N x 6 finite values (N >= 1), or the lead is outside
            [0, N).
        g2p.config.ConfigError: (a ValueError) a feedback setting outside its documented range; the message
            names the field.
        InverseMapFormatError: (a ValueError) the map's weights (see `map_from_weights`).
    """
    n = len(goal.desired)
    if n == 0 or n % N_INPUTS:
        raise ValueError(f"desired kinematics: {n} values, not a positive multiple of {N_INPUTS}")
    desired = np.asarray(goal.desired, dtype=np.float64).reshape(-1, N_INPUTS)
    feedback = FeedbackConfig(
        p_gain_per_s=tuple(float(v) for v in goal.p_gain_per_s),
        i_gain_per_s2=tuple(float(v) for v in goal.i_gain_per_s2),
        velocity_gain=tuple(float(v) for v in goal.velocity_gain),
        integral_limit_rad_s=float(goal.integral_limit_rad_s),
        correction_limit_rad_s=float(goal.correction_limit_rad_s),
        delay_ticks=int(goal.delay_ticks),
    )
    inverse_map = map_from_weights(
        goal.inverse_map.arrays, int(goal.inverse_map.format_version), "inverse_map"
    )
    return Trajectory(desired, inverse_map, feedback, int(goal.lead_ticks))
