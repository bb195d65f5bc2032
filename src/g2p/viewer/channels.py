"""The viewer's Foxglove channels and the messages it logs on them (foxglove-sdk).

Channels (the names the shipped layout, g2p.viewer.layout, shows):

| topic | encoding, schema | one message per |
| --- | --- | --- |
| /view/scene | protobuf foxglove.SceneUpdate | scene frame (at most `scene_rate_hz` a second of wall time) |
| /view/joints | JSON, g2p.JointFrame | rig tick: measured and desired angles, foot, belt |
| /view/attempts | JSON, g2p.AttemptSummary | finished attempt: reward, best, sigma, energy, tracking error |

Scene entities, in frame "treadmill" (the URDF's root: x forward, y across the belt, z up, belt surface
z = 0): "leg" (thigh, shank and foot pad as lines, joints as spheres, a label), "belt" (the belt and its
marks, which move with it), "foot_path" (the foot's recent path) and "desired_foot_path" (the attempt's
desired cycle, deleted between attempts). Every message's log time is the tick's (or event's) stamp.
"""

from __future__ import annotations

import math
from typing import Any

from foxglove import Channel, Context
from foxglove.channels import SceneUpdateChannel
from foxglove.messages import (
    Color,
    CubePrimitive,
    LinePrimitive,
    LinePrimitiveLineType,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneEntityDeletion,
    SceneUpdate,
    SpherePrimitive,
    TextPrimitive,
    Timestamp,
    Vector3,
)

from g2p.description import FloatArray, LegDescription
from g2p.viewer.state import AttemptSummary, JointFrame, SceneFrame

FRAME_ID = "treadmill"
SCENE_TOPIC = "/view/scene"
JOINTS_TOPIC = "/view/joints"
ATTEMPTS_TOPIC = "/view/attempts"

_NUMBER_OR_NULL = {"type": ["number", "null"]}
JOINTS_SCHEMA: dict[str, Any] = {
    "title": "g2p.JointFrame",
    "type": "object",
    "properties": {
        "stamp_s": {"type": "number", "description": "tick stamp (s, the rig's clock)"},
        "proximal_rad": {"type": "number", "description": "hip angle, measured (rad)"},
        "distal_rad": {"type": "number", "description": "knee angle, measured (rad)"},
        "proximal_desired_rad": {**_NUMBER_OR_NULL, "description": "hip angle, desired (rad)"},
        "distal_desired_rad": {**_NUMBER_OR_NULL, "description": "knee angle, desired (rad)"},
        "proximal_velocity_rad_s": {"type": "number", "description": "hip velocity (rad/s)"},
        "distal_velocity_rad_s": {"type": "number", "description": "knee velocity (rad/s)"},
        "foot_x_m": {"type": "number", "description": "foot, forward of the hip axis (m)"},
        "foot_z_m": {"type": "number", "description": "foot, above the belt surface (m)"},
        "belt_displacement_mm": {"type": "number", "description": "belt travel since the rig started (mm)"},
        "attempt": {"type": "integer", "description": "attempt being played (0: none)"},
        "tick": {"type": "integer", "description": "tick of the attempt (-1: none)"},
    },
}
ATTEMPTS_SCHEMA: dict[str, Any] = {
    "title": "g2p.AttemptSummary",
    "type": "object",
    "properties": {
        "attempt": {"type": "integer"},
        "phase": {"type": "string"},
        "control": {"type": "string", "description": "open or closed loop"},
        "reward_mm": {**_NUMBER_OR_NULL, "description": "belt travel (mm)"},
        "best_reward_mm": {**_NUMBER_OR_NULL, "description": "best reward so far (mm)"},
        "sigma": {**_NUMBER_OR_NULL, "description": "exploitation standard deviation"},
        "energy_j": {**_NUMBER_OR_NULL, "description": "electrical energy (J)"},
        "tracking_rmse_rad": {**_NUMBER_OR_NULL, "description": "tracking RMSE (rad)"},
        "tracking_mse_deg2": {**_NUMBER_OR_NULL, "description": "tracking MSE (deg^2)"},
    },
}

_THIGH = Color(r=0.75, g=0.75, b=0.8, a=1.0)
_SHANK = Color(r=0.6, g=0.6, b=0.7, a=1.0)
_PAD = Color(r=0.1, g=0.1, b=0.1, a=1.0)
_JOINT = Color(r=0.9, g=0.5, b=0.2, a=1.0)
_BELT = Color(r=0.2, g=0.2, b=0.2, a=1.0)
_MARK = Color(r=0.85, g=0.85, b=0.85, a=1.0)
_ACTUAL = Color(r=0.12, g=0.47, b=0.71, a=1.0)  # matplotlib's C0 and C1, as in the report's figures
_DESIRED = Color(r=1.0, g=0.5, b=0.05, a=1.0)
_BELT_THICKNESS_M = 0.02
_MARK_WIDTH_M = 0.006


def _finite(value: float) -> float | None:
    """JSON has no NaN: unmeasured values are null."""
    return value if math.isfinite(value) else None


def joints_message(frame: JointFrame) -> dict[str, Any]:
    """The /view/joints message of a tick."""
    d = frame.desired_rad
    return {
        "stamp_s": frame.stamp_ns * 1e-9,
        "proximal_rad": float(frame.position_rad[0]),
        "distal_rad": float(frame.position_rad[1]),
        "proximal_desired_rad": float(d[0]) if d is not None else None,
        "distal_desired_rad": float(d[1]) if d is not None else None,
        "proximal_velocity_rad_s": float(frame.velocity_rad_s[0]),
        "distal_velocity_rad_s": float(frame.velocity_rad_s[1]),
        "foot_x_m": float(frame.foot_m[0]),
        "foot_z_m": float(frame.foot_m[1]),
        "belt_displacement_mm": frame.belt_displacement_mm,
        "attempt": frame.attempt,
        "tick": frame.tick,
    }


def attempt_message(summary: AttemptSummary) -> dict[str, Any]:
    """The /view/attempts message of a finished attempt."""
    return {
        "attempt": summary.attempt,
        "phase": summary.phase,
        "control": summary.control,
        "reward_mm": _finite(summary.reward_mm),
        "best_reward_mm": _finite(summary.best_reward_mm),
        "sigma": _finite(summary.sigma),
        "energy_j": _finite(summary.energy_j),
        "tracking_rmse_rad": _finite(summary.tracking_rmse_rad),
        "tracking_mse_deg2": _finite(summary.tracking_mse_deg2),
    }


def _point(xz: FloatArray) -> Point3:
    return Point3(x=float(xz[0]), y=0.0, z=float(xz[1]))


def _at(x: float, y: float, z: float) -> Pose:
    return Pose(position=Vector3(x=x, y=y, z=z), orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0))


def _line(points: FloatArray, color: Color, thickness_m: float, loop: bool = False) -> LinePrimitive:
    return LinePrimitive(
        type=LinePrimitiveLineType.LineLoop if loop else LinePrimitiveLineType.LineStrip,
        pose=_at(0.0, 0.0, 0.0),
        thickness=thickness_m,
        points=[_point(p) for p in points],
        color=color,
    )


def _stamp(stamp_ns: int) -> Timestamp:
    return Timestamp(sec=stamp_ns // 1_000_000_000, nsec=stamp_ns % 1_000_000_000)


def scene_message(frame: SceneFrame, description: LegDescription) -> SceneUpdate:
    """The /view/scene update of a scene frame."""
    stamp = _stamp(frame.stamp_ns)
    hip, knee, ankle = frame.keypoints[:3]
    d = description
    leg = SceneEntity(
        timestamp=stamp,
        frame_id=FRAME_ID,
        id="leg",
        lines=[
            _line(frame.keypoints[0:2], _THIGH, 2 * d.thigh.radius_m),
            _line(frame.keypoints[1:3], _SHANK, 2 * d.shank.radius_m),
            _line(frame.keypoints[2:4], _PAD, 2 * d.foot.radius_m),
        ],
        spheres=[
            SpherePrimitive(
                pose=_at(float(p[0]), 0.0, float(p[1])), size=Vector3(x=s, y=s, z=s), color=_JOINT
            )
            for p, s in ((hip, 0.03), (knee, 0.025), (ankle, 0.02))
        ],
        texts=[
            TextPrimitive(
                pose=_at(0.0, 0.0, d.hip_height_m + 0.08),
                billboard=True,
                font_size=14.0,
                scale_invariant=True,
                color=Color(r=1.0, g=1.0, b=1.0, a=1.0),
                text=frame.label,
            )
        ],
    )
    width = 2 * d.belt_half_width_m
    belt = SceneEntity(
        timestamp=stamp,
        frame_id=FRAME_ID,
        id="belt",
        cubes=[
            CubePrimitive(
                pose=_at(0.0, 0.0, -_BELT_THICKNESS_M / 2),
                size=Vector3(x=2 * frame.belt_half_length_m, y=width, z=_BELT_THICKNESS_M),
                color=_BELT,
            ),
            *(
                CubePrimitive(
                    pose=_at(float(x), 0.0, 0.0005),
                    size=Vector3(x=_MARK_WIDTH_M, y=width, z=0.001),
                    color=_MARK,
                )
                for x in frame.belt_marks_x
            ),
        ],
    )
    entities = [leg, belt]
    deletions = []
    if len(frame.trail) >= 2:
        entities.append(
            SceneEntity(
                timestamp=stamp, frame_id=FRAME_ID, id="foot_path", lines=[_line(frame.trail, _ACTUAL, 0.004)]
            )
        )
    if frame.desired_foot_path is not None:
        entities.append(
            SceneEntity(
                timestamp=stamp,
                frame_id=FRAME_ID,
                id="desired_foot_path",
                lines=[_line(frame.desired_foot_path, _DESIRED, 0.004, loop=True)],
            )
        )
    else:
        deletions.append(SceneEntityDeletion(timestamp=stamp, id="desired_foot_path"))
    return SceneUpdate(deletions=deletions, entities=entities)


class ViewChannels:
    """The viewer's channels in one Foxglove context.

    Args:
        context: the context the channels log into (a WebSocket server or an MCAP file is its sink).
    """

    def __init__(self, context: Context) -> None:
        self.scene = SceneUpdateChannel(SCENE_TOPIC, context=context)
        self.joints = Channel(JOINTS_TOPIC, schema=JOINTS_SCHEMA, context=context)
        self.attempts = Channel(ATTEMPTS_TOPIC, schema=ATTEMPTS_SCHEMA, context=context)

    def log_joints(self, frame: JointFrame) -> None:
        """Log a tick on /view/joints."""
        self.joints.log(joints_message(frame), log_time=frame.stamp_ns)

    def log_scene(self, frame: SceneFrame, description: LegDescription) -> None:
        """Log a scene frame on /view/scene."""
        self.scene.log(scene_message(frame, description), log_time=frame.stamp_ns)

    def log_attempt(self, summary: AttemptSummary) -> None:
        """Log a finished attempt on /view/attempts."""
        self.attempts.log(attempt_message(summary), log_time=summary.stamp_ns)
