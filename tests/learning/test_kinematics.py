"""Preprocessing: resampling of jittered stamps, differentiators against analytic derivatives, edges."""

from __future__ import annotations

import math

import numpy as np
import pytest

from g2p.learning.kinematics import (
    ActivationResampling,
    Differentiator,
    PreprocessConfig,
    Resampling,
    check_stamps,
    derivative_kernels,
    differentiate,
    drop_transition,
    recording_pairs,
    resample,
    resample_held,
    training_pairs,
    uniform_grid,
)
from g2p.plant import Recording
from g2p.validation import ConfigError

FS = 78.0
DT = 1.0 / FS
METHODS = [PreprocessConfig(differentiator=d) for d in Differentiator]


def jittered_stamps(rng: np.random.Generator, duration_s: float) -> np.ndarray:
    """Stamps of a rig ticking at N(78, 5) Hz, starting at 3.0 s."""
    n = int(duration_s * FS)
    return 3.0 + np.concatenate([[0.0], np.cumsum(1.0 / rng.normal(FS, 5.0, n))])


def sine(t: np.ndarray, amp: float = 0.4, f_hz: float = 1.0) -> tuple[np.ndarray, ...]:
    w = 2 * np.pi * f_hz
    return amp * np.sin(w * t), amp * w * np.cos(w * t), -amp * w * w * np.sin(w * t)


def test_five_point_rule_on_a_sine_matches_its_hand_computed_response() -> None:
    # sum_k c_k sin(w(t + k dt)) = cos(wt) (sin(w dt) + 2 sin(2 w dt)) / 5 exactly; twice: -G^2 sin(wt).
    amp, w = 0.4, 2 * np.pi * 3.0
    t = np.arange(400) * DT
    q = np.stack([amp * np.sin(w * t), np.zeros_like(t)], axis=1)
    kin = differentiate(q, PreprocessConfig(differentiator=Differentiator.FIVE_POINT))
    tt = t[4:-4]
    gain = (np.sin(w * DT) + 2 * np.sin(2 * w * DT)) / (5 * DT)
    np.testing.assert_allclose(kin[:, 2], amp * gain * np.cos(w * tt), atol=1e-10)
    np.testing.assert_allclose(kin[:, 4], -amp * gain**2 * np.sin(w * tt), atol=1e-8)


def test_central_differences_on_a_sine_match_their_hand_computed_response() -> None:
    amp, w = 0.4, 2 * np.pi * 3.0
    t = np.arange(400) * DT
    q = np.stack([np.zeros_like(t), amp * np.sin(w * t)], axis=1)
    kin = differentiate(q, PreprocessConfig(differentiator=Differentiator.CENTRAL))
    tt = t[1:-1]
    np.testing.assert_allclose(kin[:, 3], amp * np.sin(w * DT) / DT * np.cos(w * tt), atol=1e-10)
    np.testing.assert_allclose(kin[:, 5], amp * (2 * np.cos(w * DT) - 2) / DT**2 * np.sin(w * tt), atol=1e-8)


@pytest.mark.parametrize(
    ("config", "dq_tol", "ddq_tol"),
    [
        # Tolerances relative to the analytic amplitudes (2.51 rad/s, 15.8 rad/s^2 for 0.4 rad at 1 Hz):
        # five-point twice is biased by its low-pass gain (-1.7 % dq, -3.4 % ddq at 1 Hz); central by
        # sinc-like gains (-0.2 %, -0.1 %); Savitzky-Golay w=9 p=5 is exact to < 0.01 % at 1 Hz.
        (METHODS[0], 0.02, 0.04),
        (METHODS[1], 0.0001, 0.0001),
        (METHODS[2], 0.003, 0.002),
    ],
)
def test_derivatives_of_a_sampled_sine(config: PreprocessConfig, dq_tol: float, ddq_tol: float) -> None:
    t = np.arange(800) * DT
    q, dq, ddq = sine(t)
    kin = differentiate(np.stack([q, -q], axis=1), config)
    e = config.edge
    tt = slice(e, len(t) - e)
    np.testing.assert_allclose(kin[:, 0], q[tt], atol=0)
    amp_v, amp_a = np.max(np.abs(dq)), np.max(np.abs(ddq))
    assert np.max(np.abs(kin[:, 2] - dq[tt])) < dq_tol * amp_v
    assert np.max(np.abs(kin[:, 3] + dq[tt])) < dq_tol * amp_v
    assert np.max(np.abs(kin[:, 4] - ddq[tt])) < ddq_tol * amp_a
    assert np.max(np.abs(kin[:, 5] + ddq[tt])) < ddq_tol * amp_a


@pytest.mark.parametrize("config", METHODS)
def test_rows_are_aligned_with_grid_samples_and_edges_dropped(config: PreprocessConfig) -> None:
    # Every differentiator is exact on a quadratic, so any misalignment of rows would show.
    t = np.arange(50) * DT
    q = np.stack([0.3 + 2.0 * t - 1.5 * t**2, -1.0 * t + 4.0 * t**2], axis=1)
    kin = differentiate(q, config)
    e = config.edge
    assert kin.shape == (50 - 2 * e, 6)
    tt = t[e : 50 - e]
    np.testing.assert_allclose(kin[:, :2], q[e : 50 - e], atol=0)
    np.testing.assert_allclose(kin[:, 2], 2.0 - 3.0 * tt, atol=1e-9)
    np.testing.assert_allclose(kin[:, 3], -1.0 + 8.0 * tt, atol=1e-9)
    np.testing.assert_allclose(kin[:, 4], -3.0, atol=1e-7)
    np.testing.assert_allclose(kin[:, 5], 8.0, atol=1e-7)


def test_edges_of_each_method() -> None:
    assert PreprocessConfig(differentiator=Differentiator.CENTRAL).edge == 1
    assert PreprocessConfig(differentiator=Differentiator.FIVE_POINT).edge == 4
    assert PreprocessConfig(differentiator=Differentiator.SAVGOL, savgol_window=11).edge == 5


def test_too_short_segment_raises() -> None:
    with pytest.raises(ValueError, match="q: need shape"):
        differentiate(np.zeros((8, 2)))


def test_uniform_grid_spans_the_stamps() -> None:
    t = jittered_stamps(np.random.default_rng(0), 10.0)
    grid = uniform_grid(t, FS)
    assert grid[0] == t[0]
    assert grid[-1] <= t[-1] < grid[-1] + DT
    np.testing.assert_allclose(np.diff(grid), DT, rtol=1e-9)


@pytest.mark.parametrize("method", list(Resampling))
def test_resampling_jittered_stamps_recovers_the_signal(method: Resampling) -> None:
    # 0.4 rad at 1 Hz and 0.2 rad at 3 Hz. Linear interpolation's error is bounded by h^2 max|d2q/dt2| / 8
    # with h the longest interval (~2.4e-3 rad here); the cubic spline's is O(h^4), below 2e-5 rad.
    rng = np.random.default_rng(1)
    t = jittered_stamps(rng, 20.0)

    def signal(tt: np.ndarray) -> np.ndarray:
        return np.stack([sine(tt)[0], sine(tt, 0.2, 3.0)[0]], axis=1)

    grid = uniform_grid(t, FS)
    out = resample(t, signal(t), grid, method)
    assert out.shape == (len(grid), 2)
    h = np.max(np.diff(t))
    max_ddq = np.array([0.4 * (2 * np.pi) ** 2, 0.2 * (6 * np.pi) ** 2])
    tol = h**2 * max_ddq / 8 if method is Resampling.LINEAR else np.full(2, 2e-5)
    assert np.all(np.max(np.abs(out - signal(grid)), axis=0) < tol)


def test_held_resampling_returns_the_command_of_the_containing_tick() -> None:
    t = np.array([0.0, 1.0, 2.0, 3.0])
    a = np.array([[0.1], [0.2], [0.3], [0.4]])
    out = resample_held(t, a, np.array([0.0, 0.5, 1.0, 1.01, 2.99, 3.0]))
    np.testing.assert_array_equal(out[:, 0], [0.1, 0.2, 0.2, 0.3, 0.4, 0.4])


@pytest.mark.parametrize(
    ("stamps", "match"),
    [
        ([0.0, 0.01, 0.01, 0.02], "increase strictly"),
        ([0.0, 0.01, 0.5, 0.51], "gap of 0.4900 s after sample 1"),
        ([0.0, math.nan, 0.02], "non-finite"),
        ([0.0], "N >= 2"),
    ],
)
def test_bad_stamps_raise(stamps: list[float], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        check_stamps(stamps, max_gap_s=0.1)


def test_drop_transition_drops_the_first_quarter() -> None:
    x = np.arange(100.0)[:, None] * np.ones((1, 6))
    y = np.arange(100.0)[:, None] * np.ones((1, 3))
    kx, ky = drop_transition(0.25, x, y)
    assert len(kx) == len(ky) == 75
    assert kx[0, 0] == ky[0, 0] == 25.0
    (odd,) = drop_transition(0.25, np.arange(10.0))
    np.testing.assert_array_equal(odd, np.arange(3.0, 10.0))  # ceil(2.5) = 3 rows dropped
    (none,) = drop_transition(0.0, np.arange(10.0))
    assert len(none) == 10


@pytest.mark.parametrize(
    ("fraction", "arrays", "match"),
    [
        (1.0, (np.zeros(4),), "fraction"),
        (-0.1, (np.zeros(4),), "fraction"),
        (0.25, (np.zeros(4), np.zeros(5)), "lengths differ"),
    ],
)
def test_drop_transition_rejects(fraction: float, arrays: tuple[np.ndarray, ...], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        drop_transition(fraction, *arrays)


def jittered_segment(seed: int, duration_s: float = 20.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = jittered_stamps(rng, duration_s)
    q = np.stack([sine(t)[0], sine(t, 0.3, 0.5)[0]], axis=1)
    q = np.round(q / (2 * np.pi / 2**14)) * (2 * np.pi / 2**14)  # 14-bit encoders
    a = np.repeat(rng.uniform(0.15, 1.0, (len(t) // 10 + 1, 3)), 10, axis=0)[: len(t)]
    return t, q, a


def test_training_pairs_from_jittered_samples() -> None:
    t, q, a = jittered_segment(2)
    cfg = PreprocessConfig()
    pairs = training_pairs(t, q, a, cfg)
    grid = uniform_grid(t, FS)
    e = cfg.edge
    assert len(pairs) == len(grid) - 2 * e
    np.testing.assert_allclose(pairs.t_s, grid[e : len(grid) - e])
    assert np.all(np.isfinite(pairs.kinematics))
    # Against the analytic kinematics at the grid stamps, the error is the 14-bit quantization noise
    # (sd = LSB / sqrt(12)) passed through the differentiator's kernels: sd * ||kernel|| / dt^k. Allow 25 %.
    tt = pairs.t_s
    truth = np.stack(
        [
            sine(tt)[0],
            sine(tt, 0.3, 0.5)[0],
            sine(tt)[1],
            sine(tt, 0.3, 0.5)[1],
            sine(tt)[2],
            sine(tt, 0.3, 0.5)[2],
        ],
        axis=1,
    )
    sd = 2 * np.pi / 2**14 / math.sqrt(12)
    k_vel, k_acc = derivative_kernels(cfg)
    expected = np.repeat([sd, sd * np.linalg.norm(k_vel) / DT, sd * np.linalg.norm(k_acc) / DT**2], 2)
    rms = np.sqrt(np.mean((pairs.kinematics - truth) ** 2, axis=0))
    assert np.all(rms < 1.25 * expected)
    # Activations: the command of the tick that contains the time `command_lead_ticks` + 0.5 grid intervals
    # earlier (the middle of the tick that ended `command_lead_ticks` ticks before the kinematics).
    idx = np.searchsorted(t, pairs.t_s - (cfg.command_lead_ticks + 0.5) * DT, side="left")
    np.testing.assert_array_equal(pairs.activation, a[idx])


@pytest.mark.parametrize("lead", [0, 3, 6])
def test_training_pairs_pair_motion_with_the_command_lead_ticks_earlier(lead: int) -> None:
    t, q, a = jittered_segment(4)
    cfg = PreprocessConfig(command_lead_ticks=lead)
    pairs = training_pairs(t, q, a, cfg)
    grid = uniform_grid(t, FS)
    start = max(cfg.edge, lead + 1)
    np.testing.assert_allclose(pairs.t_s, grid[start : len(grid) - cfg.edge])
    middle = grid[start : len(grid) - cfg.edge] - (lead + 0.5) * DT
    np.testing.assert_array_equal(pairs.activation, a[np.searchsorted(t, middle, side="left")])


@pytest.mark.parametrize("lead", [0, 3, 6])
def test_boundary_pairing_is_selectable(lead: int) -> None:
    t, q, a = jittered_segment(4)
    cfg = PreprocessConfig(command_lead_ticks=lead, command_at_tick_middle=False)
    pairs = training_pairs(t, q, a, cfg)
    grid = uniform_grid(t, FS)
    start = max(cfg.edge, lead)
    np.testing.assert_allclose(pairs.t_s, grid[start : len(grid) - cfg.edge])
    held = a[np.searchsorted(t, grid, side="left")]
    np.testing.assert_array_equal(pairs.activation, held[start - lead : len(grid) - cfg.edge - lead])


def ticks_around_nominal(rng: np.random.Generator, n: int, jitter_s: float) -> np.ndarray:
    """End-of-tick stamps k / 78 s + U(-jitter, +jitter): jitter that does not accumulate; the first exact."""
    return 2.0 + np.arange(n) * DT + np.concatenate([[0.0], rng.uniform(-jitter_s, jitter_s, n - 1)])


@pytest.mark.parametrize("lead", [0, 1, 3])
def test_middle_pairing_gives_the_tick_that_ended_lead_ticks_before(lead: int) -> None:
    # Known answer: tick i's activation is its index, its stamp the end of the tick, within a quarter tick
    # of i / 78 s. The row at the end of tick k must get tick k - lead's command: the command that acted
    # during the whole tick that ended `lead` ticks before the angle was read. This is how an attempt plays
    # a map with that lead (the activation for row k + lead during tick k).
    rng = np.random.default_rng(11)
    n = 400
    t = ticks_around_nominal(rng, n, 0.25 * DT)
    q = np.zeros((n, 2))
    a = np.repeat(np.arange(n, dtype=np.float64)[:, None], 3, axis=1)
    cfg = PreprocessConfig(command_lead_ticks=lead)
    pairs = training_pairs(t, q, a, cfg)
    k = np.rint((pairs.t_s - t[0]) * FS).astype(int)  # the tick whose end each row sits at
    np.testing.assert_array_equal(pairs.activation[:, 0], k - lead)
    # The boundary pairing is ambiguous: a grid stamp a hair after the end of tick k - lead holds the next
    # tick's command, which had not yet acted on the angle: about half of the rows here.
    boundary_cfg = PreprocessConfig(command_lead_ticks=lead, command_at_tick_middle=False)
    boundary = training_pairs(t, q, a, boundary_cfg)
    late = boundary.activation[:, 0] - (np.rint((boundary.t_s - t[0]) * FS) - lead)
    assert set(np.unique(late)) == {0.0, 1.0}
    assert 0.2 < np.mean(late == 1.0) < 0.8


def test_training_pairs_drop_the_transition_on_the_grid() -> None:
    t, q, a = jittered_segment(3)
    full = training_pairs(t, q, a)
    dropped = training_pairs(t, q, a, drop_fraction=0.25)
    n_grid = len(uniform_grid(t, FS))
    assert dropped.t_s[0] == pytest.approx(t[0] + math.ceil(0.25 * n_grid) * DT)
    assert dropped.t_s[-1] == full.t_s[-1]
    # Dropping happens after differentiation: the kept rows are the same numbers as without dropping.
    np.testing.assert_array_equal(dropped.kinematics, full.kinematics[-len(dropped) :])


def test_linear_activation_resampling_is_selectable() -> None:
    t, q, a = jittered_segment(4)
    pairs = training_pairs(
        t, q, a, PreprocessConfig(activation_resampling=ActivationResampling.LINEAR, command_lead_ticks=0)
    )
    expected = np.stack([np.interp(pairs.t_s, t, a[:, m]) for m in range(3)], axis=1)
    np.testing.assert_allclose(pairs.activation, expected)


def test_short_segment_gives_no_pairs() -> None:
    t, q, a = jittered_segment(5, duration_s=0.08)
    assert len(training_pairs(t, q, a)) == 0


def test_recording_pairs_use_the_recording_fields() -> None:
    t, q, a = jittered_segment(6, duration_s=5.0)
    n = len(t)
    rec = Recording(
        t_s=t,
        activation=a,
        position_rad=q,
        velocity_rad_s=np.zeros((n, 2)),
        belt_mm=np.zeros(n),
        belt_velocity_mm_s=np.zeros(n),
        current_a=np.zeros((n, 3)),
        power_w=np.zeros((n, 3)),
        energy_j=np.zeros((n, 3)),
    )
    a_pairs, b_pairs = recording_pairs(rec, drop_fraction=0.25), training_pairs(t, q, a, drop_fraction=0.25)
    np.testing.assert_array_equal(a_pairs.kinematics, b_pairs.kinematics)
    np.testing.assert_array_equal(a_pairs.activation, b_pairs.activation)


@pytest.mark.parametrize(
    ("bad", "match"),
    [
        ({"position_rad": np.zeros((10, 3))}, "position_rad: expected shape"),
        ({"activation": np.full((10, 3), np.nan)}, "activation: non-finite"),
    ],
)
def test_training_pairs_reject_bad_arrays(bad: dict[str, np.ndarray], match: str) -> None:
    args = {"t_s": np.arange(10) * DT, "position_rad": np.zeros((10, 2)), "activation": np.zeros((10, 3))}
    with pytest.raises(ValueError, match=match):
        training_pairs(**{**args, **bad})


@pytest.mark.parametrize(
    ("field", "kwargs"),
    [
        ("rate_hz", {"rate_hz": 0.0}),
        ("differentiator", {"differentiator": "spline"}),
        ("resampling", {"resampling": "nearest"}),
        ("savgol_window", {"savgol_window": 8}),
        ("savgol_polyorder", {"savgol_polyorder": 1}),
        ("savgol_polyorder", {"savgol_window": 5, "savgol_polyorder": 5}),
        ("max_gap_s", {"max_gap_s": 0.001}),
        ("transition_fraction", {"transition_fraction": 1.0}),
    ],
)
def test_invalid_config_names_the_field(field: str, kwargs: dict[str, object]) -> None:
    with pytest.raises(ConfigError, match=f"^{field}:"):
        PreprocessConfig(**kwargs)  # type: ignore[arg-type]


def test_config_accepts_strings_for_enums() -> None:
    cfg = PreprocessConfig(differentiator="central", resampling="linear")  # type: ignore[arg-type]
    assert cfg.differentiator is Differentiator.CENTRAL
    assert cfg.resampling is Resampling.LINEAR
