"""Limit cycles: a 10-D feature vector -> a smooth closed trajectory in joint space, with its derivatives.

Spoke k points at angle theta_k = 2 pi k / n_spokes in the joint-angle plane; feature f_k sets its length:

    point_k = centre + f_k * radius * (sin theta_k, cos theta_k)      (per joint: proximal, distal)

The points are visited with equal time between them, one every `samples_per_segment` rig ticks, and joined by
a periodic cubic spline (scipy CubicSpline, bc_type='periodic'): it passes exactly through the points, is C2
across the wrap, and gives velocities and accelerations analytically. The authors smoothed with a circular
moving average instead, which pulls the path inside the points it should visit and leaves derivatives to
finite differences (docs/ALGORITHM.md).

With both radii positive the path runs clockwise in the (q_prox, q_dist) plane (spoke 0 at +q_dist, spoke
n/4 at +q_prox); a negative radius mirrors that joint and so reverses the direction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline

from g2p.plant import NOMINAL_TICK_HZ
from g2p.validation import require, require_length, require_positive, require_range

FloatArray = NDArray[np.float64]

TREADMILL_FEATURE_BOUNDS = (0.15, 1.0)
"""Feature bounds for locomotion on the treadmill (paper)."""
AIR_FEATURE_BOUNDS = (0.2, 0.8)
"""Feature bounds for free cyclical movements in the air (paper)."""


@dataclass(frozen=True)
class LimitCycleConfig:
    """Shape and timing of limit cycles (defaults: the paper's hardware numbers, treadmill bounds).

    Attributes:
        centre_rad: centre of the spokes (rad): proximal, distal; the middle of the joints' usable range. The
            default is the simulated leg's (g2p.sim.LIMIT_CYCLE_WORKSPACE); on hardware, set it from the rig's
            calibration (the authors used the middle of their encoders' range, 68 and 297.5 encoder degrees).
        radius_rad: signed spoke scale per joint (rad): the half-range of the usable joint range (the authors:
            65 and 47.5 encoder degrees). The sign of one joint's radius sets the direction the cycle runs
            (see the module docstring); the default runs counter-clockwise in the (proximal, distal) plane,
            the stepping direction: the hip extends while the knee is near straight (stance) and flexes while
            the knee is bent (swing).
        n_spokes: spokes, and so features and segments per cycle.
        samples_per_segment: rig ticks between consecutive spoke points (8 in the authors' code: 80 ticks,
            ~1.03 s per cycle).
        rate_hz: rig tick rate at which the cycle is sampled (Hz).
        feature_low: smallest allowed feature (feature units: spoke length as a fraction of the radius).
        feature_high: largest allowed feature (feature units).
        n_cycles: cycles played back to back in one attempt.
    """

    centre_rad: tuple[float, float] = (0.0, -0.6)
    radius_rad: tuple[float, float] = (-0.6, 0.6)
    n_spokes: int = 10
    samples_per_segment: int = 8
    rate_hz: float = NOMINAL_TICK_HZ
    feature_low: float = TREADMILL_FEATURE_BOUNDS[0]
    feature_high: float = TREADMILL_FEATURE_BOUNDS[1]
    n_cycles: int = 20

    def __post_init__(self) -> None:
        require_length(self.centre_rad, 2, "centre_rad")
        require_length(self.radius_rad, 2, "radius_rad")
        # Lists (e.g. from ROS parameters) become tuples so the config stays hashable and immutable.
        object.__setattr__(self, "centre_rad", (float(self.centre_rad[0]), float(self.centre_rad[1])))
        object.__setattr__(self, "radius_rad", (float(self.radius_rad[0]), float(self.radius_rad[1])))
        require(
            all(r != 0.0 for r in self.radius_rad), "radius_rad", f"must be non-zero, got {self.radius_rad}"
        )
        require(self.n_spokes >= 3, "n_spokes", f"must be >= 3, got {self.n_spokes}")
        require(
            self.samples_per_segment >= 1,
            "samples_per_segment",
            f"must be >= 1, got {self.samples_per_segment}",
        )
        require_positive(self.rate_hz, "rate_hz")
        require_range(self.feature_low, self.feature_high, "feature_low, feature_high", 0.0)
        require(self.n_cycles >= 1, "n_cycles", f"must be >= 1, got {self.n_cycles}")

    @classmethod
    def treadmill(cls, **overrides: object) -> LimitCycleConfig:
        """The treadmill preset: features in [0.15, 1]."""
        return cls(
            **{
                "feature_low": TREADMILL_FEATURE_BOUNDS[0],  # type: ignore[arg-type]
                "feature_high": TREADMILL_FEATURE_BOUNDS[1],
                **overrides,
            }
        )

    @classmethod
    def in_air(cls, **overrides: object) -> LimitCycleConfig:
        """The in-air preset: features in [0.2, 0.8]."""
        return cls(
            **{
                "feature_low": AIR_FEATURE_BOUNDS[0],  # type: ignore[arg-type]
                "feature_high": AIR_FEATURE_BOUNDS[1],
                **overrides,
            }
        )

    @property
    def samples_per_cycle(self) -> int:
        """Rig ticks per cycle, M = n_spokes * samples_per_segment (80 by default)."""
        return self.n_spokes * self.samples_per_segment

    @property
    def period_s(self) -> float:
        """Duration of one cycle (s): M / rate_hz (~1.026 s by default)."""
        return self.samples_per_cycle / self.rate_hz

    @property
    def spoke_angles_rad(self) -> FloatArray:
        """theta_k = 2 pi k / n_spokes, shape (n_spokes,) (rad)."""
        return 2.0 * np.pi * np.arange(self.n_spokes) / self.n_spokes


def check_features(features: ArrayLike, config: LimitCycleConfig | None = None) -> FloatArray:
    """Return features as a float array of shape (n_spokes,), or raise naming the offending value.

    Raises:
        ValueError: wrong shape, a non-finite value, or a value outside [feature_low, feature_high].
    """
    cfg = config or LimitCycleConfig()
    f = np.asarray(features, dtype=np.float64)
    if f.shape != (cfg.n_spokes,):
        raise ValueError(f"features: expected shape ({cfg.n_spokes},), got {f.shape}")
    for k, value in enumerate(f):
        if not math.isfinite(value):
            raise ValueError(f"features[{k}] = {value} is not finite")
        if not cfg.feature_low <= value <= cfg.feature_high:
            raise ValueError(f"features[{k}] = {value} is outside [{cfg.feature_low}, {cfg.feature_high}]")
    return f


def spoke_points(features: ArrayLike, config: LimitCycleConfig | None = None) -> FloatArray:
    """The points the cycle visits, in order.

    Args:
        features: spoke lengths, shape (n_spokes,), within the bounds.
        config: cycle parameters; the defaults when None.

    Returns:
        Joint angles of the points, shape (n_spokes, 2) (rad).
    """
    cfg = config or LimitCycleConfig()
    f = check_features(features, cfg)
    theta = cfg.spoke_angles_rad
    unit = np.stack([np.sin(theta), np.cos(theta)], axis=1)
    centre = np.asarray(cfg.centre_rad, dtype=np.float64)
    radius = np.asarray(cfg.radius_rad, dtype=np.float64)
    return np.asarray(centre + f[:, None] * radius * unit, dtype=np.float64)


def cycle_spline(features: ArrayLike, config: LimitCycleConfig | None = None) -> CubicSpline:
    """The periodic cubic spline q(t) through the spoke points, point k at t = k * period / n_spokes.

    Args:
        features: spoke lengths, shape (n_spokes,).
        config: cycle parameters; the defaults when None.

    Returns:
        A spline of period `config.period_s` (s) with values of shape (2,) (rad); `.derivative(1)` and
        `.derivative(2)` give rad/s and rad/s^2.
    """
    cfg = config or LimitCycleConfig()
    points = spoke_points(features, cfg)
    t = np.arange(cfg.n_spokes + 1) * (cfg.period_s / cfg.n_spokes)
    return CubicSpline(t, np.vstack([points, points[:1]]), bc_type="periodic", axis=0)


def cycle_kinematics(features: ArrayLike, config: LimitCycleConfig | None = None) -> FloatArray:
    """One cycle sampled at the rig rate, starting at spoke 0.

    Args:
        features: spoke lengths, shape (n_spokes,), within [feature_low, feature_high].
        config: cycle parameters; the defaults when None.

    Returns:
        Kinematics [q_prox, q_dist, dq_prox, dq_dist, ddq_prox, ddq_dist], shape (M, 6) with
        M = samples_per_cycle (rad, rad/s, rad/s^2); row m is at t = m / rate_hz, and row
        k * samples_per_segment is exactly spoke point k.

    Raises:
        ValueError: invalid features (the message names the index and value).
    """
    cfg = config or LimitCycleConfig()
    spline = cycle_spline(features, cfg)
    t = np.arange(cfg.samples_per_cycle) / cfg.rate_hz
    return np.hstack([spline(t), spline(t, 1), spline(t, 2)])


def repeat_cycles(cycle: ArrayLike, n_cycles: int = 20) -> FloatArray:
    """Play a cycle back to back (seamless, since the cycle is periodic).

    Args:
        cycle: one cycle, shape (M, D).
        n_cycles: repetitions (>= 1; 20 per attempt in the paper).

    Returns:
        Shape (n_cycles * M, D).
    """
    if n_cycles < 1:
        raise ValueError(f"n_cycles: must be >= 1, got {n_cycles}")
    return np.tile(np.asarray(cycle, dtype=np.float64), (n_cycles, 1))


def attempt_kinematics(features: ArrayLike, config: LimitCycleConfig | None = None) -> FloatArray:
    """The target kinematics of a whole attempt: `config.n_cycles` cycles, shape (n_cycles * M, 6)."""
    cfg = config or LimitCycleConfig()
    return repeat_cycles(cycle_kinematics(features, cfg), cfg.n_cycles)
