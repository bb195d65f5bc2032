"""Conversion between the rig contract's messages and the core's types, in one place.

Tick samples and recordings (the rig topics, RigSamples), inverse maps (InverseMapWeights' arrays, the
g2p.inverse_map format) and closed-loop trajectories (RunTrajectory goals).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from builtin_interfaces.msg import Time
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from g2p.inverse_map import N_INPUTS, InverseMap, InverseMapFormatError
from g2p.plant import JOINT_NAMES, N_JOINTS, N_MOTORS, Recording, TickSample
from g2p.rig.closed_loop import FeedbackConfig, Trajectory
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
        g2p.validation.ConfigError: (a ValueError) a feedback setting outside its documented range; the
            message names the field.
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
