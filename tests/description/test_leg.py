"""The leg's forward kinematics against positions computed by hand, and the description's validation."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from g2p.description import Joint, LegDescription, Link, foot_path, forward_kinematics

# Round numbers: hip 1 m up, thigh 0.3 m, shank 0.2 m, ankle to pad centre 0.05 m, pad radius 0.01 m,
# so the straight leg's sole is 0.56 m below the hip.
LEG = LegDescription(
    hip_height_m=1.0,
    thigh=Link("thigh", 0.3, 0.02, 0.4, (0.0, -0.15), 0.003),
    shank=Link("shank", 0.2, 0.015, 0.3, (0.0, -0.1), 0.001),
    foot=Link("foot", 0.05, 0.01, 0.1, (0.0, -0.04), 0.0001),
    pad_half_length_m=0.03,
    joints=(Joint("proximal", -1.0, 1.0), Joint("distal", -1.5, 0.0)),
    belt_half_width_m=0.1,
)


COS30 = math.sqrt(3) / 2


@pytest.mark.parametrize(
    ("q", "expected"),
    [
        # hanging straight down
        ((0.0, 0.0), [(0.0, 1.0), (0.0, 0.7), (0.0, 0.5), (0.0, 0.44)]),
        # hip flexed 90 deg: the straight leg points forward (+x), level with the hip
        ((math.pi / 2, 0.0), [(0.0, 1.0), (0.3, 1.0), (0.5, 1.0), (0.56, 1.0)]),
        # hip flexed 90 deg, knee flexed 90 deg: the shank hangs straight down from the knee
        ((math.pi / 2, -math.pi / 2), [(0.0, 1.0), (0.3, 1.0), (0.3, 0.8), (0.3, 0.74)]),
        # knee flexed 90 deg alone: the shank points backward (-x)
        ((0.0, -math.pi / 2), [(0.0, 1.0), (0.0, 0.7), (-0.2, 0.7), (-0.26, 0.7)]),
        # hip extended 30 deg: the straight leg leans back, each point at r (-sin 30, -cos 30)
        (
            (-math.pi / 6, 0.0),
            [(0.0, 1.0), (-0.15, 1 - 0.3 * COS30), (-0.25, 1 - 0.5 * COS30), (-0.28, 1 - 0.56 * COS30)],
        ),
    ],
)
def test_keypoints_match_hand_computed_positions(
    q: tuple[float, float], expected: list[tuple[float, float]]
) -> None:
    np.testing.assert_allclose(forward_kinematics(LEG, q), expected, atol=1e-12)


def test_many_postures_at_once_match_one_at_a_time() -> None:
    q = np.random.default_rng(0).uniform(-1.5, 1.5, size=(7, 2))
    points = forward_kinematics(LEG, q)
    assert points.shape == (7, 4, 2)
    for row, posture in zip(points, q, strict=True):
        np.testing.assert_allclose(row, forward_kinematics(LEG, posture), atol=1e-15)
    np.testing.assert_allclose(foot_path(LEG, q), points[:, 3])
    assert foot_path(LEG, (0.0, 0.0)).shape == (1, 2)


def test_every_link_keeps_its_length_in_any_posture() -> None:
    points = forward_kinematics(LEG, np.random.default_rng(1).uniform(-2, 2, size=(20, 2)))
    segments = np.linalg.norm(np.diff(points, axis=1), axis=-1)
    np.testing.assert_allclose(segments, np.broadcast_to([0.3, 0.2, 0.06], segments.shape), atol=1e-12)
    assert LEG.reach_m == pytest.approx(0.56)


def test_joint_angles_must_come_in_pairs() -> None:
    with pytest.raises(ValueError, match="2 columns"):
        forward_kinematics(LEG, [0.1, 0.2, 0.3])


@pytest.mark.parametrize(
    "change",
    [
        {"hip_height_m": 0.0},
        {"belt_half_width_m": -0.1},
        {"pad_half_length_m": math.nan},
        {"thigh": replace(LEG.thigh, length_m=-0.3)},
        {"foot": replace(LEG.foot, mass_kg=math.inf)},
    ],
)
def test_sizes_must_be_finite_and_non_negative(change: dict[str, object]) -> None:
    with pytest.raises(ValueError, match="finite, non-negative"):
        replace(LEG, **change)


def test_joints_must_be_proximal_then_distal() -> None:
    with pytest.raises(ValueError, match="proximal, distal"):
        replace(LEG, joints=(LEG.joints[1], LEG.joints[0]))
