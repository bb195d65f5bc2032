"""From timestamped rig samples to 6-D kinematics on a uniform grid, and training pairs for the inverse map.

The rig ticks at about 78 Hz with jitter, so samples are first put on a uniform grid using their stamps;
angular velocities and accelerations then come from the angles by a finite-impulse-response
differentiator. Every differentiator needs a few samples on each side, so the first and last `edge`
grid samples of a segment are dropped rather than estimated from one-sided stencils: edge artefacts
never reach the training data.

Kinematics rows are [q_prox, q_dist, dq_prox, dq_dist, ddq_prox, ddq_dist] (rad, rad/s, rad/s^2).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline
from scipy.signal import savgol_coeffs

from g2p.plant import NOMINAL_TICK_HZ, Recording
from g2p.validation import ConfigError, require, require_positive

FloatArray = NDArray[np.float64]

N_KINEMATICS = 6

# The authors' 5-point derivative stencil, x[n-2] .. x[n+2], divided by 10 dt.
_FIVE_POINT = np.array([-2.0, -1.0, 0.0, 1.0, 2.0]) / 10.0


class Differentiator(str, enum.Enum):
    """How velocities and accelerations are estimated from uniformly sampled angles."""

    FIVE_POINT = "five_point"
    """The authors' rule [-2x(n-2) - x(n-1) + x(n+1) + 2x(n+2)] / (10 dt), applied twice for accelerations."""
    SAVGOL = "savgol"
    """Savitzky-Golay: derivatives of a local least-squares polynomial (window and order: config fields)."""
    CENTRAL = "central"
    """Plain central differences: (x(n+1) - x(n-1)) / (2 dt) and (x(n+1) - 2x(n) + x(n-1)) / dt^2."""


class Resampling(str, enum.Enum):
    """How the angles are interpolated from the jittered stamps onto the uniform grid."""

    LINEAR = "linear"
    """Straight lines between samples (what the authors did)."""
    CUBIC = "cubic"
    """A not-a-knot cubic spline through the samples (C2, so it adds no kinks for the differentiator)."""


class ActivationResampling(str, enum.Enum):
    """How the activations are put on the uniform grid."""

    HOLD = "hold"
    """The activation applied during the tick that contains the grid time (commands are step-wise)."""
    LINEAR = "linear"
    """Linear interpolation between ticks, as for the angles (what the authors did)."""


@dataclass(frozen=True)
class PreprocessConfig:
    """Resampling and differentiation parameters (defaults: chosen by benchmarks/bench_differentiators.py).

    Attributes:
        rate_hz: rate of the uniform grid (Hz); the rig's nominal tick rate.
        resampling: interpolation of the angles onto the grid.
        activation_resampling: interpolation of the activations onto the grid.
        differentiator: velocity and acceleration estimator.
        savgol_window: savitzky-Golay window (samples, odd).
        savgol_polyorder: savitzky-Golay polynomial order (>= 2 so the second derivative exists, <
            savgol_window).
        max_gap_s: longest interval between two stamps that is still interpolated (s); a longer one means lost
            samples.
        transition_fraction: leading fraction (dimensionless) of an attempt dropped before refinement (the
            move away from the rest posture).
        command_lead_ticks: grid samples between a command and the motion it causes: kinematics at sample k
            are paired with the activation of sample k - command_lead_ticks, and attempts play each activation
            that much early. The motors' current lag and the tendons' stretch delay the motion; pairing
            kinematics with the activation of the same sample teaches the map a late command, and refinement
            then tracks worse with every attempt (docs/ALGORITHM.md, "Command lead"). 3 samples (38 ms) suits
            the simulated rig; measure it on hardware.
        command_at_tick_middle: with HOLD activations, pair kinematics at grid time t with the command held at
            t - (lead + 0.5) grid intervals, the middle of the tick that ended `command_lead_ticks` ticks
            before t, instead of at t - lead intervals. Grid stamps fall on tick boundaries (the grid starts
            at the first tick's end), where the held command is ambiguous: depending on the jitter, about half
            of the pairs got the command of the next tick, which had not yet acted on the angles it was paired
            with. An attempt plays the activation for desired row k + lead during tick k and compares the
            angle at the end of tick k + lead with that row: lead whole ticks from the end of the command's
            tick to the kinematics, which the middle pairing reproduces (docs/ALGORITHM.md, "Command
            pairing"). False: the boundary pairing.
    """

    rate_hz: float = NOMINAL_TICK_HZ
    resampling: Resampling = Resampling.CUBIC
    activation_resampling: ActivationResampling = ActivationResampling.HOLD
    differentiator: Differentiator = Differentiator.SAVGOL
    savgol_window: int = 9
    savgol_polyorder: int = 5
    max_gap_s: float = 0.1
    transition_fraction: float = 0.25
    command_lead_ticks: int = 3
    command_at_tick_middle: bool = True

    def __post_init__(self) -> None:
        require_positive(self.rate_hz, "rate_hz")
        for name, kind in (
            ("resampling", Resampling),
            ("activation_resampling", ActivationResampling),
            ("differentiator", Differentiator),
        ):
            value = getattr(self, name)
            try:
                object.__setattr__(self, name, kind(value))
            except ValueError as err:
                choices = [m.value for m in kind]
                raise ConfigError(f"{name}: must be one of {choices}, got {value!r}") from err
        require(
            self.savgol_window >= 3 and self.savgol_window % 2 == 1,
            "savgol_window",
            f"must be an odd integer >= 3, got {self.savgol_window}",
        )
        require(
            2 <= self.savgol_polyorder < self.savgol_window,
            "savgol_polyorder",
            f"must satisfy 2 <= savgol_polyorder < savgol_window ({self.savgol_window}), "
            f"got {self.savgol_polyorder}",
        )
        require(
            math.isfinite(self.max_gap_s) and self.max_gap_s > 1.0 / self.rate_hz,
            "max_gap_s",
            f"must be finite and longer than one grid interval ({1.0 / self.rate_hz} s), "
            f"got {self.max_gap_s}",
        )
        require(
            0.0 <= self.transition_fraction < 1.0,
            "transition_fraction",
            f"must be in [0, 1), got {self.transition_fraction}",
        )
        require(
            isinstance(self.command_lead_ticks, int) and 0 <= self.command_lead_ticks <= 20,
            "command_lead_ticks",
            f"must be an integer in [0, 20], got {self.command_lead_ticks!r}",
        )

    @property
    def dt_s(self) -> float:
        """Grid interval (s)."""
        return 1.0 / self.rate_hz

    @property
    def edge(self) -> int:
        """Grid samples dropped at each end of a segment by the differentiator."""
        return len(derivative_kernels(self)[1]) // 2


def derivative_kernels(config: PreprocessConfig) -> tuple[FloatArray, FloatArray]:
    """Correlation kernels of the configured differentiator, for a unit grid interval.

    Returns:
        (velocity kernel, acceleration kernel), each of odd length, centred; divide the correlation by dt
        and dt^2 respectively. The acceleration kernel is the longer (or equal) one.
    """
    if config.differentiator is Differentiator.FIVE_POINT:
        # Applying a correlation kernel twice correlates with the kernel convolved with itself.
        return _FIVE_POINT, np.convolve(_FIVE_POINT, _FIVE_POINT)
    if config.differentiator is Differentiator.SAVGOL:
        w, p = config.savgol_window, config.savgol_polyorder
        return (
            savgol_coeffs(w, p, deriv=1, use="dot").astype(np.float64),
            savgol_coeffs(w, p, deriv=2, use="dot").astype(np.float64),
        )
    return np.array([-0.5, 0.0, 0.5]), np.array([1.0, -2.0, 1.0])


def uniform_grid(t_s: ArrayLike, rate_hz: float) -> FloatArray:
    """Uniform stamps from the first stamp, every 1 / rate_hz, not past the last stamp.

    Args:
        t_s: increasing stamps, shape (N,) (s).
        rate_hz: grid rate (Hz).

    Returns:
        Grid stamps, shape (M,) (s).
    """
    t = np.asarray(t_s, dtype=np.float64)
    # The small tolerance keeps a grid point that lands on the last stamp up to rounding.
    m = math.floor((t[-1] - t[0]) * rate_hz + 1e-9) + 1
    return np.asarray(t[0] + np.arange(m) / rate_hz, dtype=np.float64)


def check_stamps(t_s: ArrayLike, max_gap_s: float) -> FloatArray:
    """Validate sample stamps: shape (N,) with N >= 2, finite, strictly increasing, no gap over max_gap_s.

    Raises:
        ValueError: naming the first offending sample.
    """
    t = np.asarray(t_s, dtype=np.float64)
    if t.ndim != 1 or len(t) < 2:
        raise ValueError(f"t_s: need shape (N >= 2,), got {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError(f"t_s: non-finite stamp at index {int(np.argmin(np.isfinite(t)))}")
    dt = np.diff(t)
    if np.any(dt <= 0.0):
        i = int(np.argmax(dt <= 0.0))
        raise ValueError(f"t_s: stamps must increase strictly, t[{i}] = {t[i]} >= t[{i + 1}] = {t[i + 1]}")
    if np.any(dt > max_gap_s):
        i = int(np.argmax(dt > max_gap_s))
        raise ValueError(f"t_s: gap of {dt[i]:.4f} s after sample {i} exceeds max_gap_s = {max_gap_s} s")
    return t


def resample(t_s: FloatArray, values: FloatArray, t_grid: FloatArray, method: Resampling) -> FloatArray:
    """Interpolate samples taken at stamps `t_s` onto `t_grid`.

    Args:
        t_s: increasing stamps, shape (N,) (s).
        values: samples, shape (N, D).
        t_grid: query stamps within [t_s[0], t_s[-1]], shape (M,) (s).
        method: interpolation method.

    Returns:
        Interpolated values, shape (M, D).
    """
    if method is Resampling.CUBIC:
        return np.asarray(CubicSpline(t_s, values, axis=0)(t_grid), dtype=np.float64)
    return np.stack([np.interp(t_grid, t_s, values[:, d]) for d in range(values.shape[1])], axis=1)


def resample_held(t_s: FloatArray, values: FloatArray, t_grid: FloatArray) -> FloatArray:
    """Sample piecewise-constant commands on `t_grid`: row i holds over (t_s[i-1], t_s[i]].

    A tick's stamp is the end of the tick during which its activation was applied, so the command active at
    time t is the one of the first tick stamped at or after t.

    Args:
        t_s: increasing tick stamps, shape (N,) (s).
        values: commands, shape (N, D).
        t_grid: query stamps within [t_s[0], t_s[-1]], shape (M,) (s).

    Returns:
        Commands, shape (M, D).
    """
    idx = np.searchsorted(t_s, t_grid, side="left")
    return values[np.minimum(idx, len(t_s) - 1)]


def differentiate(q: ArrayLike, config: PreprocessConfig | None = None) -> FloatArray:
    """Angles on the uniform grid to kinematics, dropping `config.edge` samples at each end.

    Args:
        q: joint angles sampled every `config.dt_s`, shape (M, 2) (rad).
        config: the differentiator; the defaults when None.

    Returns:
        Kinematics [q, dq, ddq], shape (M - 2 * edge, 6) (rad, rad/s, rad/s^2); row i is grid sample
        i + edge.

    Raises:
        ValueError: q is not (M, 2) with M > 2 * edge.
    """
    cfg = config or PreprocessConfig()
    angles = np.asarray(q, dtype=np.float64)
    e = cfg.edge
    if angles.ndim != 2 or angles.shape[1] != 2 or angles.shape[0] <= 2 * e:
        raise ValueError(
            f"q: need shape (M > {2 * e}, 2) for the {cfg.differentiator.value} differentiator, "
            f"got {angles.shape}"
        )
    k_vel, k_acc = derivative_kernels(cfg)
    m = angles.shape[0]

    def apply(kernel: FloatArray, scale: float) -> FloatArray:
        h = len(kernel) // 2
        # 'valid' correlation, then keep the rows where the longest (acceleration) kernel is valid too.
        out = np.stack([np.correlate(angles[:, j], kernel, mode="valid") for j in range(2)], axis=1)
        return out[e - h : m - e - h] / scale

    return np.hstack([angles[e : m - e], apply(k_vel, cfg.dt_s), apply(k_acc, cfg.dt_s**2)])


def drop_transition(fraction: float, *arrays: FloatArray) -> tuple[FloatArray, ...]:
    """Drop the leading `fraction` of rows (rounded up) of arrays that share their first dimension.

    Args:
        fraction: share of the rows to drop, in [0, 1) (0.25 in the paper: the move from the rest posture).
        *arrays: arrays of equal length N along axis 0.

    Returns:
        The arrays without their first ceil(fraction * N) rows.

    Raises:
        ValueError: fraction out of range or lengths differ.
    """
    if not 0.0 <= fraction < 1.0:
        raise ValueError(f"fraction: must be in [0, 1), got {fraction}")
    lengths = {len(a) for a in arrays}
    if len(lengths) > 1:
        raise ValueError(f"arrays: lengths differ: {sorted(lengths)}")
    n = lengths.pop() if lengths else 0
    cut = math.ceil(fraction * n - 1e-9)
    return tuple(a[cut:] for a in arrays)


@dataclass(frozen=True)
class TrainingPairs:
    """Kinematics and the activations that produced them, on the uniform grid.

    Attributes:
        t_s: grid stamps, shape (K,) (s).
        kinematics: [q, dq, ddq] rows, shape (K, 6) (rad, rad/s, rad/s^2): the inverse map's inputs.
        activation: activations, shape (K, 3): the inverse map's targets.
    """

    t_s: FloatArray
    kinematics: FloatArray
    activation: FloatArray

    def __len__(self) -> int:
        return len(self.t_s)


def training_pairs(
    t_s: ArrayLike,
    position_rad: ArrayLike,
    activation: ArrayLike,
    config: PreprocessConfig | None = None,
    drop_fraction: float = 0.0,
) -> TrainingPairs:
    """Turn one segment of timestamped rig samples into (kinematics, activation) pairs on a uniform grid.

    Resamples the angles and activations on a grid at `config.rate_hz`, differentiates the angles, drops
    the differentiator's edge samples, then drops the leading `drop_fraction` of the segment's grid.

    Args:
        t_s: tick stamps, shape (N,) (s), strictly increasing, no gap over `config.max_gap_s`.
        position_rad: joint angles at the stamps, shape (N, 2) (rad).
        activation: activation applied during each tick, shape (N, 3).
        config: preprocessing parameters; the defaults when None.
        drop_fraction: leading share of the segment to drop, in [0, 1): 0 for babbling,
            `config.transition_fraction` for an attempt.

    Returns:
        The pairs (possibly empty when the segment is shorter than the differentiator's stencil).

    Raises:
        ValueError: invalid stamps, shapes, non-finite values or drop_fraction.
    """
    cfg = config or PreprocessConfig()
    t = check_stamps(t_s, cfg.max_gap_s)
    q = _check_rows(position_rad, len(t), 2, "position_rad")
    a = _check_rows(activation, len(t), 3, "activation")
    if not 0.0 <= drop_fraction < 1.0:
        raise ValueError(f"drop_fraction: must be in [0, 1), got {drop_fraction}")
    grid = uniform_grid(t, cfg.rate_hz)
    e = cfg.edge
    lead = cfg.command_lead_ticks
    # Leading rows to drop on the grid: the transition, but at least the differentiator's edge and the
    # command lead (row k needs the activation of row k - lead, or of the middle of the tick before it).
    hold = cfg.activation_resampling is ActivationResampling.HOLD
    middle = hold and cfg.command_at_tick_middle
    start = max(math.ceil(drop_fraction * len(grid) - 1e-9), e, lead + 1 if middle else lead)
    stop = len(grid) - e
    if stop <= start:
        empty = np.empty((0,), dtype=np.float64)
        return TrainingPairs(empty, np.empty((0, N_KINEMATICS)), np.empty((0, 3)))
    kin = differentiate(resample(t, q, grid, cfg.resampling), cfg)  # rows e .. len(grid) - e
    kin = kin[start - e : stop - e]
    if middle:
        act = resample_held(t, a, grid[start:stop] - (lead + 0.5) * cfg.dt_s)
    elif hold:
        act = resample_held(t, a, grid)[start - lead : stop - lead]
    else:
        act = resample(t, a, grid, Resampling.LINEAR)[start - lead : stop - lead]
    return TrainingPairs(grid[start:stop], kin, act)


def recording_pairs(
    recording: Recording, config: PreprocessConfig | None = None, drop_fraction: float = 0.0
) -> TrainingPairs:
    """`training_pairs` of a `Recording` (uses its t_s, position_rad and activation)."""
    return training_pairs(recording.t_s, recording.position_rad, recording.activation, config, drop_fraction)


def _check_rows(values: ArrayLike, n: int, width: int, name: str) -> FloatArray:
    v = np.asarray(values, dtype=np.float64)
    if v.shape != (n, width):
        raise ValueError(f"{name}: expected shape ({n}, {width}), got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name}: non-finite value in row {int(np.argwhere(~np.isfinite(v))[0, 0])}")
    return v
