"""Conversion between the rig contract's messages and the core's sample types, in one place."""

from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from g2p.plant import JOINT_NAMES, N_JOINTS, N_MOTORS, Recording, TickSample
from g2p_interfaces.msg import MotorActivation, MotorPower, RigSamples, Treadmill

FRAME_ID = "leg"


def time_from_seconds(t_s: float) -> Time:
    """A builtin_interfaces/Time from seconds (rounded to the nanosecond)."""
    ns = stamp_ns(t_s)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


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


def stamp_ns(t_s: float) -> int:
    """Integer nanoseconds of a stamp in seconds (as `time_from_seconds` rounds it)."""
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
