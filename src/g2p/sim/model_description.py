"""The leg's description (g2p.description) read from the compiled MuJoCo model the simulator runs.

`python -m g2p.sim.model_description > src/g2p/description/models/leg.urdf` regenerates the packaged URDF
(g2p.description.urdf) from the packaged model at the treadmill carriage height.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import mujoco
import numpy as np

from g2p.description import Joint, LegDescription, Link
from g2p.description.urdf import leg_urdf
from g2p.sim.config import TREADMILL_CARRIAGE_HEIGHT_M, MujocoLegConfig, packaged_model_path
from g2p.sim.model import CARRIAGE_BODY, ModelError, load_leg_model

# Bodies of the three links, their joints, and the geoms drawn for them.
_LINK_BODIES = ("thigh", "shank", "foot")
_JOINTS = ("proximal", "distal")
_PAD_GEOM = "footpad"
_BELT_GEOM = "belt"
_HINGE_AXIS = np.array([0.0, -1.0, 0.0])


def _id(model: mujoco.MjModel, kind: mujoco.mjtObj, name: str) -> int:
    found = int(mujoco.mj_name2id(model, kind, name))
    if found < 0:
        raise ModelError(f"model has no {kind.name.removeprefix('mjOBJ_').lower()} named {name!r}")
    return found


def _inertia_about_y(model: mujoco.MjModel, body: int) -> float:
    """Moment of inertia of `body` about the y axis through its centre of mass (kg m^2)."""
    rotation = np.zeros(9)
    mujoco.mju_quat2Mat(rotation, model.body_iquat[body])
    r = rotation.reshape(3, 3)
    return float((r @ np.diag(model.body_inertia[body]) @ r.T)[1, 1])


def _link(model: mujoco.MjModel, name: str, length_m: float, radius_m: float) -> Link:
    body = _id(model, mujoco.mjtObj.mjOBJ_BODY, name)
    com = model.body_ipos[body]
    return Link(
        name=name,
        length_m=length_m,
        radius_m=radius_m,
        mass_kg=float(model.body_mass[body]),
        com_m=(float(com[0]), float(com[2])),
        inertia_kg_m2=_inertia_about_y(model, body),
    )


def _below(model: mujoco.MjModel, child: str) -> float:
    """How far the origin of body `child` lies straight below its parent's (m); the leg is planar."""
    x, y, z = model.body_pos[_id(model, mujoco.mjtObj.mjOBJ_BODY, child)]
    if abs(x) > 1e-9 or abs(y) > 1e-9 or z >= 0.0:
        raise ModelError(
            f"body {child!r} must sit straight below its parent (0, 0, -length), got {(x, y, z)}"
        )
    return float(-z)


def _link_radius(model: mujoco.MjModel, body_name: str) -> float:
    """Radius of the first capsule or cylinder geom of a body: its visual thickness (m)."""
    body = _id(model, mujoco.mjtObj.mjOBJ_BODY, body_name)
    shapes = (int(mujoco.mjtGeom.mjGEOM_CAPSULE), int(mujoco.mjtGeom.mjGEOM_CYLINDER))
    for g in range(model.ngeom):
        if model.geom_bodyid[g] == body and model.geom_type[g] in shapes:
            return float(model.geom_size[g][0])
    raise ModelError(f"body {body_name!r} has no capsule or cylinder geom to draw it by")


def leg_description(model: mujoco.MjModel) -> LegDescription:
    """The description of a compiled leg model (g2p.sim.model.load_leg_model's `model`).

    Raises:
        ModelError: the model lacks a body, joint or geom the description needs, or is not planar.
    """
    joints = []
    for name in _JOINTS:
        jid = _id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if model.jnt_type[jid] != int(mujoco.mjtJoint.mjJNT_HINGE) or not np.allclose(
            model.jnt_axis[jid], _HINGE_AXIS
        ):
            raise ModelError(f"joint {name!r} must be a hinge about -y (the leg is planar)")
        lower, upper = model.jnt_range[jid] if model.jnt_limited[jid] else (-np.pi, np.pi)
        joints.append(Joint(name, float(lower), float(upper)))
    pad = _id(model, mujoco.mjtObj.mjOBJ_GEOM, _PAD_GEOM)
    if model.geom_type[pad] != int(mujoco.mjtGeom.mjGEOM_CAPSULE):
        raise ModelError(f"geom {_PAD_GEOM!r} must be a capsule along x")
    belt = _id(model, mujoco.mjtObj.mjOBJ_GEOM, _BELT_GEOM)
    carriage = _id(model, mujoco.mjtObj.mjOBJ_BODY, CARRIAGE_BODY)
    return LegDescription(
        hip_height_m=float(model.body_pos[carriage][2]),
        thigh=_link(model, "thigh", _below(model, "shank"), _link_radius(model, "thigh")),
        shank=_link(model, "shank", _below(model, "foot"), _link_radius(model, "shank")),
        foot=_link(model, "foot", float(-model.geom_pos[pad][2]), float(model.geom_size[pad][0])),
        pad_half_length_m=float(model.geom_size[pad][1]),
        joints=(joints[0], joints[1]),
        belt_half_width_m=float(model.geom_size[belt][1]),
    )


def config_description(config: MujocoLegConfig) -> LegDescription:
    """The description of the leg `MujocoLeg(config)` simulates, from its compiled model (no settling).

    Raises:
        ModelError: the model lacks an element the plant or the description needs.
    """
    return leg_description(load_leg_model(config.resolved_model_path, config.carriage_height_m).model)


def main(argv: Sequence[str] | None = None) -> int:
    """Print a leg model's URDF (`> src/g2p/description/models/leg.urdf` regenerates the packaged one)."""
    parser = argparse.ArgumentParser(
        prog="python -m g2p.sim.model_description",
        description="Print the URDF (robot_description) of the leg's MuJoCo model.",
    )
    parser.add_argument(
        "--model", default="", help="MJCF file (default: the packaged g2p/description/models/leg.xml)"
    )
    parser.add_argument(
        "--carriage-height-m",
        type=float,
        default=TREADMILL_CARRIAGE_HEIGHT_M,
        help=f"height of the hip axis above the belt (m, default {TREADMILL_CARRIAGE_HEIGHT_M})",
    )
    args = parser.parse_args(argv)
    path = Path(args.model) if args.model else packaged_model_path()
    sys.stdout.write(leg_urdf(leg_description(load_leg_model(path, args.carriage_height_m).model)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
