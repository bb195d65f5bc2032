"""Limit cycles: spoke points, periodic C2 spline, derivatives, direction, feature validation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from g2p.learning.limit_cycle import (
    AIR_FEATURE_BOUNDS,
    TREADMILL_FEATURE_BOUNDS,
    LimitCycleConfig,
    attempt_kinematics,
    check_features,
    cycle_kinematics,
    cycle_spline,
    repeat_cycles,
    spoke_points,
)
from g2p.validation import ConfigError

FEATURES = np.array([0.3, 0.9, 0.5, 1.0, 0.15, 0.7, 0.45, 0.6, 0.95, 0.2])


def signed_area(points: np.ndarray) -> float:
    """Shoelace area in the (q_prox, q_dist) plane: > 0 counter-clockwise, < 0 clockwise."""
    x, y = points[:, 0], points[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def test_spoke_points_by_hand() -> None:
    cfg = LimitCycleConfig(centre_rad=(0.1, -0.2), radius_rad=(1.0, 2.0))
    p = spoke_points(np.ones(10), cfg)
    np.testing.assert_allclose(p[0], [0.1, -0.2 + 2.0], atol=1e-15)  # theta = 0: straight along +q_dist
    np.testing.assert_allclose(p[5], [0.1, -0.2 - 2.0], atol=1e-15)  # theta = pi
    f = np.full(10, 0.5)
    p = spoke_points(f, cfg)
    theta = 2 * np.pi * 2 / 10
    np.testing.assert_allclose(p[2], [0.1 + 0.5 * math.sin(theta), -0.2 + 0.5 * 2.0 * math.cos(theta)])


def test_default_cycle_shape_and_timing() -> None:
    cfg = LimitCycleConfig()
    k = cycle_kinematics(FEATURES, cfg)
    assert k.shape == (80, 6)
    assert cfg.samples_per_cycle == 80
    assert cfg.period_s == pytest.approx(80 / 78)


def test_default_cycle_spans_the_simulated_rigs_workspace_in_the_stepping_direction() -> None:
    from g2p.sim import LIMIT_CYCLE_WORKSPACE

    cfg = LimitCycleConfig()
    assert cfg.centre_rad == LIMIT_CYCLE_WORKSPACE.centre_rad
    assert cfg.radius_rad == LIMIT_CYCLE_WORKSPACE.stepping_radius_rad


def test_passes_through_spoke_points_at_spoke_times() -> None:
    cfg = LimitCycleConfig()
    k = cycle_kinematics(FEATURES, cfg)
    np.testing.assert_allclose(k[:: cfg.samples_per_segment, :2], spoke_points(FEATURES, cfg), atol=1e-12)


def test_closed_and_c2_across_the_wrap() -> None:
    cfg = LimitCycleConfig()
    s = cycle_spline(FEATURES, cfg)
    period, eps = cfg.period_s, 1e-7
    # Values and first two derivatives agree at both ends; just before and just after the wrap they differ
    # by at most 2 eps times the next derivative (bounded: the third derivative is piecewise constant).
    bound = [np.max(np.abs(s(np.linspace(0, period, 5000), order + 1))) for order in range(3)]
    for order in range(3):
        np.testing.assert_allclose(s(period, order), s(0.0, order), atol=1e-9 * max(1.0, bound[order]))
        assert np.all(np.abs(s(period - eps, order) - s(eps, order)) <= 2 * eps * bound[order] * (1 + 1e-6))


def test_repeated_cycles_sample_one_periodic_function() -> None:
    # Two cycles back to back are the samples of the same periodic spline at m / rate for m < 2M: the seam
    # is invisible.
    cfg = LimitCycleConfig()
    two = repeat_cycles(cycle_kinematics(FEATURES, cfg), 2)
    s = cycle_spline(FEATURES, cfg)
    t = np.arange(len(two)) / cfg.rate_hz
    np.testing.assert_allclose(two, np.hstack([s(t), s(t, 1), s(t, 2)]), atol=1e-9)


def test_velocities_and_accelerations_match_finite_differences() -> None:
    cfg = LimitCycleConfig()
    s = cycle_spline(FEATURES, cfg)
    h = 1e-5
    t = np.linspace(0, cfg.period_s, 997, endpoint=False)
    jerk = np.max(np.abs(s(t, 3)))
    # Central differences err by O(h^2) on smooth pieces; at a knot (t = 0 here) the jump of the piecewise
    # constant third derivative adds up to h * max|jerk| / 2 to the difference quotient of the velocity.
    np.testing.assert_allclose((s(t + h) - s(t - h)) / (2 * h), s(t, 1), atol=1e-6)
    np.testing.assert_allclose((s(t + h, 1) - s(t - h, 1)) / (2 * h), s(t, 2), atol=h * jerk / 2 + 1e-6)
    k = cycle_kinematics(FEATURES, cfg)
    tm = np.arange(cfg.samples_per_cycle) / cfg.rate_hz
    np.testing.assert_allclose(k[:, 2:4], s(tm, 1), atol=1e-12)
    np.testing.assert_allclose(k[:, 4:], s(tm, 2), atol=1e-12)


def test_smooth_acceleration_between_samples() -> None:
    # C2 with piecewise-linear acceleration: consecutive rig samples differ in ddq by at most
    # max|dddq| * dt, with the third derivative constant on each of the 10 segments.
    cfg = LimitCycleConfig()
    s = cycle_spline(FEATURES, cfg)
    k = repeat_cycles(cycle_kinematics(FEATURES, cfg), 2)
    jerk = np.max(np.abs(s(np.linspace(0, cfg.period_s, 10_000), 3)), axis=0)
    assert np.all(np.max(np.abs(np.diff(k[:, 4:], axis=0)), axis=0) <= jerk / cfg.rate_hz + 1e-9)


def test_direction_follows_the_sign_of_a_radius() -> None:
    cw = spoke_points(FEATURES, LimitCycleConfig(radius_rad=(math.radians(65.0), math.radians(47.5))))
    ccw = spoke_points(FEATURES, LimitCycleConfig(radius_rad=(-math.radians(65.0), math.radians(47.5))))
    assert signed_area(cw) < 0
    assert signed_area(ccw) > 0
    # Mirroring one joint reverses the direction but keeps the shape.
    assert signed_area(ccw) == pytest.approx(-signed_area(cw))


def test_attempt_repeats_twenty_cycles() -> None:
    cfg = LimitCycleConfig()
    a = attempt_kinematics(FEATURES, cfg)
    assert a.shape == (20 * 80, 6)
    np.testing.assert_array_equal(a[80:160], a[:80])
    assert repeat_cycles(np.zeros((5, 6))).shape == (100, 6)
    with pytest.raises(ValueError, match="n_cycles"):
        repeat_cycles(np.zeros((5, 6)), 0)


def test_presets() -> None:
    assert (
        (LimitCycleConfig.treadmill().feature_low, LimitCycleConfig.treadmill().feature_high)
        == TREADMILL_FEATURE_BOUNDS
        == (0.15, 1.0)
    )
    air = LimitCycleConfig.in_air(samples_per_segment=4)
    assert (air.feature_low, air.feature_high) == AIR_FEATURE_BOUNDS == (0.2, 0.8)
    assert air.samples_per_cycle == 40
    check_features(np.full(10, 0.8), air)
    with pytest.raises(ValueError, match=r"features\[0\] = 0.9 is outside \[0.2, 0.8\]"):
        check_features(np.full(10, 0.9), air)


@pytest.mark.parametrize(
    ("features", "match"),
    [
        (np.full(9, 0.5), r"expected shape \(10,\)"),
        (
            np.array([0.5, 0.5, 0.5, np.nan, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5]),
            r"features\[3\] = nan is not finite",
        ),
        (np.array([0.5] * 7 + [1.2, 0.5, 0.5]), r"features\[7\] = 1.2 is outside"),
        (np.array([0.1] + [0.5] * 9), r"features\[0\] = 0.1 is outside"),
    ],
)
def test_invalid_features_name_index_and_value(features: np.ndarray, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        cycle_kinematics(features)


@pytest.mark.parametrize(
    ("field", "kwargs"),
    [
        ("centre_rad", {"centre_rad": (0.0, 0.0, 0.0)}),
        ("radius_rad", {"radius_rad": (0.0, 1.0)}),
        ("radius_rad", {"radius_rad": (math.inf, 1.0)}),
        ("n_spokes", {"n_spokes": 2}),
        ("samples_per_segment", {"samples_per_segment": 0}),
        ("rate_hz", {"rate_hz": 0.0}),
        ("feature_low, feature_high", {"feature_low": 0.8, "feature_high": 0.2}),
        ("n_cycles", {"n_cycles": 0}),
    ],
)
def test_invalid_config_names_the_field(field: str, kwargs: dict[str, object]) -> None:
    with pytest.raises(ConfigError, match=f"^{field}:"):
        LimitCycleConfig(**kwargs)  # type: ignore[arg-type]
