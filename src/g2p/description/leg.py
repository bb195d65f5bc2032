"""The leg's geometry for drawing it: link lengths, joint limits, foot pad, and its forward kinematics.

One `LegDescription` is taken from the MuJoCo model the simulator runs (g2p.sim.model_description),
turned into the URDF the rig nodes publish as `robot_description` (g2p.description.urdf), and read back
from that URDF by the viewer and the report, so every drawing of the leg is the leg that ran. numpy only.

Frame (the model's, docs/SIMULATOR.md): the belt surface is z = 0, the leg faces +x, the plane of motion
is x-z, every hinge turns about -y. A positive angle is counter-clockwise seen with +x to the right and z
up; (0, 0) is the leg hanging straight down. The passive ankle is not sensed: the foot is drawn at ankle
angle 0, in line with the shank.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

# Points of the stick figure, in the order forward_kinematics returns them.
KEYPOINTS = ("hip", "knee", "ankle", "foot")


@dataclass(frozen=True)
class Link:
    """One rigid link of the leg.

    Attributes:
        name: "thigh", "shank" or "foot".
        length_m: distance along the link from its joint to the next joint (m); for the foot, from the
            ankle down to the pad's centre line.
        radius_m: radius of the link's visual cylinder (m); for the foot, the pad's radius.
        mass_kg: mass of the link (kg).
        com_m: centre of mass in the link's frame (x, z) (m).
        inertia_kg_m2: moment of inertia about the hinge axis through the centre of mass (kg m^2).
    """

    name: str
    length_m: float
    radius_m: float
    mass_kg: float
    com_m: tuple[float, float]
    inertia_kg_m2: float


@dataclass(frozen=True)
class Joint:
    """One hinge of the leg (axis -y).

    Attributes:
        name: "proximal" (hip) or "distal" (knee).
        lower_rad: lower limit (rad).
        upper_rad: upper limit (rad).
    """

    name: str
    lower_rad: float
    upper_rad: float


@dataclass(frozen=True)
class LegDescription:
    """What it takes to draw the leg and the belt under it.

    Attributes:
        hip_height_m: height of the hip axis above the belt surface (m).
        thigh: hip to knee.
        shank: knee to ankle.
        foot: ankle to the foot pad's centre line; the pad is a capsule along x.
        pad_half_length_m: half the length of the pad's straight part (m).
        joints: the sensed hinges, proximal (hip) and distal (knee).
        belt_half_width_m: half the belt's width, across the plane of motion (y) (m).
    """

    hip_height_m: float
    thigh: Link
    shank: Link
    foot: Link
    pad_half_length_m: float
    joints: tuple[Joint, Joint]
    belt_half_width_m: float

    def __post_init__(self) -> None:
        values = [self.hip_height_m, self.pad_half_length_m, self.belt_half_width_m]
        values += [v for link in self.links for v in (link.length_m, link.radius_m, link.mass_kg)]
        if not all(np.isfinite(v) and v >= 0.0 for v in values) or self.hip_height_m <= 0.0:
            raise ValueError(f"a leg description needs finite, non-negative sizes and masses: {self}")
        if tuple(j.name for j in self.joints) != ("proximal", "distal"):
            raise ValueError(f"joints must be proximal, distal; got {[j.name for j in self.joints]}")

    @property
    def links(self) -> tuple[Link, Link, Link]:
        """Thigh, shank and foot."""
        return (self.thigh, self.shank, self.foot)

    @property
    def reach_m(self) -> float:
        """Distance from the hip axis to the bottom of the pad with the leg straight (m)."""
        return self.thigh.length_m + self.shank.length_m + self.foot.length_m + self.foot.radius_m


def _down(angle_rad: FloatArray, length_m: float) -> FloatArray:
    """The vector of a link of `length_m` pointing down at zero, turned by `angle_rad`: shape (..., 2)."""
    return np.stack([length_m * np.sin(angle_rad), -length_m * np.cos(angle_rad)], axis=-1)


def forward_kinematics(description: LegDescription, position_rad: ArrayLike) -> FloatArray:
    """Where the leg's keypoints are for given joint angles.

    Args:
        description: the leg.
        position_rad: (proximal, distal) angles (rad), shape (2,) or (N, 2).

    Returns:
        The keypoints hip, knee, ankle and foot (the bottom of the pad, ankle angle 0) in the belt frame
        (x, z) (m): shape (4, 2), or (N, 4, 2) for N postures.
    """
    q = np.asarray(position_rad, dtype=np.float64)
    if q.shape[-1] != 2:
        raise ValueError(f"joint angles must have 2 columns (proximal, distal), got shape {q.shape}")
    hip_angle, knee_angle = q[..., 0], q[..., 0] + q[..., 1]
    hip = np.broadcast_to(np.array([0.0, description.hip_height_m]), (*q.shape[:-1], 2))
    knee = hip + _down(hip_angle, description.thigh.length_m)
    ankle = knee + _down(knee_angle, description.shank.length_m)
    foot = ankle + _down(knee_angle, description.foot.length_m + description.foot.radius_m)
    return np.stack([hip, knee, ankle, foot], axis=-2)


def foot_path(description: LegDescription, position_rad: ArrayLike) -> FloatArray:
    """The foot's path (bottom of the pad) for a sequence of joint angles: shape (N, 2), (x, z) (m)."""
    return forward_kinematics(description, np.atleast_2d(np.asarray(position_rad, dtype=np.float64)))[:, 3]
