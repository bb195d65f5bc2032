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
    ns = round(t_s * 1e9)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def seconds_from_time(stamp: Time) -> float:
    """Seconds of a builtin_interfaces/Time."""
    return stamp.sec + stamp.nanosec * 1e-9


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


def rig_samples_msg(recording: Recording, start_stamp: Time) -> RigSamples:
    """Pack a recording into RigSamples; times become offsets from the first tick's stamp."""
    t0 = float(recording.t_s[0]) if len(recording) else 0.0
    return RigSamples(
        start_stamp=start_stamp,
        time_s=recording.t_s - t0,
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
    """Unpack RigSamples into a Recording with absolute stamps (s).

    Raises:
        ValueError: the arrays' lengths disagree.
    """
    n = len(msg.time_s)

    def rows(values: object, width: int, name: str) -> np.ndarray:
        a = np.asarray(values, dtype=np.float64)
        if a.size != n * width:
            raise ValueError(f"RigSamples.{name}: expected {n} x {width} values, got {a.size}")
        return a.reshape(n, width)

    return Recording(
        t_s=seconds_from_time(msg.start_stamp) + np.asarray(msg.time_s, dtype=np.float64),
        activation=rows(msg.applied_activation, N_MOTORS, "applied_activation"),
        position_rad=rows(msg.position_rad, N_JOINTS, "position_rad"),
        velocity_rad_s=rows(msg.velocity_rad_s, N_JOINTS, "velocity_rad_s"),
        belt_mm=rows(msg.belt_displacement_mm, 1, "belt_displacement_mm")[:, 0],
        belt_velocity_mm_s=rows(msg.belt_velocity_mm_s, 1, "belt_velocity_mm_s")[:, 0],
        current_a=rows(msg.current_a, N_MOTORS, "current_a"),
        power_w=rows(msg.power_w, N_MOTORS, "power_w"),
        energy_j=rows(msg.energy_j, N_MOTORS, "energy_j"),
    )
