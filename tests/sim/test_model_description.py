"""The leg's URDF against the MuJoCo model, read through the mujoco API and a PyPI URDF parser (yourdfpy).

The model's numbers are read here straight from the compiled MjModel (not through g2p.sim.model_description),
the URDF's through yourdfpy, and the foot's position in a few postures is checked three ways: yourdfpy's
forward kinematics, g2p.description.forward_kinematics and MuJoCo's own, and against positions by hand.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import mujoco
import numpy as np
import pytest
import yourdfpy

from g2p.description import forward_kinematics
from g2p.description.urdf import leg_urdf, packaged_urdf_path, parse_leg_urdf
from g2p.sim import AIR_CARRIAGE_HEIGHT_M, TREADMILL_CARRIAGE_HEIGHT_M
from g2p.sim.config import packaged_model_path
from g2p.sim.model import load_leg_model
from g2p.sim.model_description import leg_description, main

REGENERATE = "python -m g2p.sim.model_description > src/g2p/description/models/leg.urdf"
HEIGHTS = [TREADMILL_CARRIAGE_HEIGHT_M, AIR_CARRIAGE_HEIGHT_M]


def _model(height_m: float) -> mujoco.MjModel:
    return load_leg_model(packaged_model_path(), height_m).model


def _urdf(text: str) -> yourdfpy.URDF:
    return yourdfpy.URDF.load(io.StringIO(text), build_scene_graph=True, load_meshes=False)


def test_the_shipped_urdf_is_the_one_generated_from_the_packaged_model(
    capsys: pytest.CaptureFixture[str],
) -> None:
    generated = leg_urdf(leg_description(_model(TREADMILL_CARRIAGE_HEIGHT_M)))
    assert main([]) == 0
    assert capsys.readouterr().out == generated
    shipped = packaged_urdf_path().read_text(encoding="utf-8")
    assert shipped == generated, (
        f"src/g2p/description/models/leg.urdf is stale: regenerate it with `{REGENERATE}`"
    )


def test_the_command_takes_a_model_and_a_carriage_height(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "leg.xml"
    path.write_text(packaged_model_path().read_text().replace('range="-55 55"', 'range="-40 50"'))
    assert main(["--model", str(path), "--carriage-height-m", "0.6"]) == 0
    leg = parse_leg_urdf(capsys.readouterr().out)
    assert leg.hip_height_m == 0.6
    assert (leg.joints[0].lower_rad, leg.joints[0].upper_rad) == (math.radians(-40), math.radians(50))


@pytest.mark.parametrize("height", HEIGHTS)
def test_lengths_axes_limits_and_masses_agree_with_the_mujoco_model(height: float) -> None:
    model = _model(height)
    urdf = _urdf(leg_urdf(leg_description(model)))
    assert urdf.validate()
    assert urdf.actuated_joint_names == ["proximal", "distal"]
    joints = {j.name: j for j in urdf.robot.joints}
    assert {n: j.type for n, j in joints.items()} == {
        "carriage": "fixed",
        "proximal": "revolute",
        "distal": "revolute",
        "ankle": "fixed",
    }
    # A joint's origin in the URDF is the MuJoCo body's position in its parent: the carriage's height, the
    # thigh at the hip, the shank at the end of the thigh, the foot at the end of the shank.
    for joint, body in [
        ("carriage", "carriage"),
        ("proximal", "thigh"),
        ("distal", "shank"),
        ("ankle", "foot"),
    ]:
        np.testing.assert_array_equal(joints[joint].origin[:3, :3], np.eye(3))
        np.testing.assert_array_equal(joints[joint].origin[:3, 3], model.body(body).pos, err_msg=joint)
    assert joints["carriage"].origin[2, 3] == height
    for name in ("proximal", "distal"):
        mj = model.joint(name)
        np.testing.assert_array_equal(joints[name].axis, mj.axis)
        assert (joints[name].limit.lower, joints[name].limit.upper) == tuple(mj.range), name
    links = {link.name: link for link in urdf.robot.links}
    for name in ("thigh", "shank", "foot"):
        body = model.body(name)
        inertial = links[name].inertial
        assert inertial.mass == body.mass[0], name
        np.testing.assert_array_equal(inertial.origin[:3, 3], body.ipos, err_msg=name)
        # MuJoCo's principal inertia, turned from the inertial frame into the body's: its yy entry.
        rotation = np.zeros(9)
        mujoco.mju_quat2Mat(rotation, body.iquat)
        r = rotation.reshape(3, 3)
        assert inertial.inertia[1, 1] == pytest.approx((r @ np.diag(body.inertia) @ r.T)[1, 1], rel=1e-12)
    pad = model.geom("footpad")
    visuals = {v.name: v for v in links["foot"].visuals}
    assert visuals["pad"].geometry.cylinder.radius == pad.size[0]
    assert visuals["pad"].geometry.cylinder.length == 2 * pad.size[1]
    np.testing.assert_array_equal(visuals["pad"].origin[:3, 3], pad.pos)
    belt = {v.name: v for v in links["treadmill"].visuals}["belt"]
    assert belt.geometry.box.size[1] == 2 * model.geom("belt").size[1]


def _mujoco_keypoints(model: mujoco.MjModel, q: tuple[float, float]) -> np.ndarray:
    """Knee, ankle and sole (x, z) by MuJoCo's kinematics, ankle angle 0, everything else at qpos 0."""
    data = mujoco.MjData(model)
    for name, angle in zip(("proximal", "distal"), q, strict=True):
        data.qpos[model.joint(name).qposadr[0]] = angle
    mujoco.mj_kinematics(model, data)
    foot = data.body("foot")
    pad = model.geom("footpad")
    sole = data.geom("footpad").xpos + foot.xmat.reshape(3, 3) @ np.array([0.0, 0.0, -pad.size[0]])
    return np.array([data.body("shank").xpos, foot.xpos, sole])[:, [0, 2]]


# (proximal, distal) and the knee, ankle and sole (bottom of the pad) by hand, for the packaged leg at the
# treadmill height: hip at z = 0.42, thigh and shank 0.2 m, sole 0.037 m below the ankle.
HAND = [
    (
        (0.0, 0.0),
        [(0.0, 0.22), (0.0, 0.02), (0.0, 0.42 - 0.437)],
    ),  # straight down: the sole 17 mm in the belt
    ((math.pi / 2, 0.0), [(0.2, 0.42), (0.4, 0.42), (0.437, 0.42)]),  # straight forward
    ((math.pi / 2, -math.pi / 2), [(0.2, 0.42), (0.2, 0.22), (0.2, 0.183)]),  # thigh forward, shank down
    ((0.0, -math.pi / 2), [(0.0, 0.22), (-0.2, 0.22), (-0.237, 0.22)]),  # knee flexed, shank back
]


@pytest.mark.parametrize(("q", "expected"), HAND)
def test_forward_kinematics_of_the_urdf_description_and_mujoco_agree_with_hand(
    q: tuple[float, float], expected: list[tuple[float, float]]
) -> None:
    model = _model(TREADMILL_CARRIAGE_HEIGHT_M)
    description = leg_description(model)
    urdf = _urdf(leg_urdf(description))
    urdf.update_cfg({"proximal": q[0], "distal": q[1]})
    to_belt = {link: urdf.get_transform(link, "treadmill") for link in ("carriage", "shank", "foot")}
    sole = to_belt["foot"] @ np.array(
        [0.0, 0.0, -(description.foot.length_m + description.foot.radius_m), 1.0]
    )
    points = np.array([to_belt["carriage"][:3, 3], to_belt["shank"][:3, 3], to_belt["foot"][:3, 3], sole[:3]])
    np.testing.assert_allclose(points[:, 1], 0.0, atol=1e-15)  # the leg stays in the x-z plane
    urdf_keypoints = points[:, [0, 2]]
    ours = forward_kinematics(description, q)
    np.testing.assert_allclose(urdf_keypoints, ours, atol=1e-12)
    np.testing.assert_allclose(ours[1:], _mujoco_keypoints(model, q), atol=1e-12)
    np.testing.assert_allclose(ours, [(0.0, 0.42), *expected], atol=1e-12)


@pytest.mark.parametrize("height", HEIGHTS)
def test_random_postures_agree_between_the_urdf_description_and_mujoco(height: float) -> None:
    model = _model(height)
    description = parse_leg_urdf(leg_urdf(leg_description(model)))
    urdf = _urdf(leg_urdf(description))
    for q in np.random.default_rng(3).uniform((-0.96, -1.75), (0.96, 0.0), size=(10, 2)):
        urdf.update_cfg({"proximal": q[0], "distal": q[1]})
        knee, ankle = (urdf.get_transform(link, "treadmill")[:3, 3][[0, 2]] for link in ("shank", "foot"))
        ours = forward_kinematics(description, q)
        np.testing.assert_allclose([knee, ankle], ours[1:3], atol=1e-12)
        np.testing.assert_allclose(ours[1:], _mujoco_keypoints(model, (q[0], q[1])), atol=1e-12)
