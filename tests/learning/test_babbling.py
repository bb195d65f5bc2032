"""Motor babbling: shape, range, dwell statistics, level distribution, independence, seeding."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from g2p.learning.babbling import BabblingConfig, babbling_activations
from g2p.validation import ConfigError

HOUR = BabblingConfig(duration_s=3600.0)


@pytest.fixture(scope="module")
def hour() -> np.ndarray:
    return babbling_activations(np.random.default_rng(1234), HOUR)


def test_default_session_is_five_minutes_at_78_hz_in_range() -> None:
    a = babbling_activations(np.random.default_rng(0))
    assert a.shape == (23_400, 3)
    assert a.min() >= 0.15
    assert a.max() <= 1.0


def test_stair_steps_hold_between_switches(hour: np.ndarray) -> None:
    # Only a small share of samples change level: the signal is piecewise constant.
    changes = np.diff(hour, axis=0) != 0
    assert 0 < changes.mean() < 0.02


def test_mean_dwell_is_one_second(hour: np.ndarray) -> None:
    # Level changes per motor are Binomial(N - 1, p = 1/78); pooled over 3 motors the relative standard error
    # of the switch rate is 1 / sqrt(3 (N - 1) p) ~ 1.0 %. Allow 4 standard errors.
    n = len(hour)
    p = HOUR.switch_probability
    switches = int(np.sum(np.diff(hour, axis=0) != 0))
    expected = 3 * (n - 1) * p
    assert abs(switches - expected) < 4 * math.sqrt(expected * (1 - p))
    mean_dwell_s = 3 * (n - 1) / switches / HOUR.rate_hz
    assert mean_dwell_s == pytest.approx(1.0, rel=4 / math.sqrt(expected))


def test_dwell_times_are_geometric(hour: np.ndarray) -> None:
    # Memoryless switching: the share of dwells longer than 2 s is (1 - p)^(2 fs) ~ e^-2 = 13.5 %.
    dwells = []
    for m in range(3):
        edges = np.flatnonzero(np.diff(hour[:, m]) != 0)
        dwells.append(np.diff(edges))
    d = np.concatenate(dwells)
    share = np.mean(d > 2 * 78)
    expected = (1 - HOUR.switch_probability) ** (2 * 78)
    assert abs(share - expected) < 4 * math.sqrt(expected * (1 - expected) / len(d))


def test_levels_are_uniform_on_015_1(hour: np.ndarray) -> None:
    levels = np.concatenate([hour[1:, m][np.diff(hour[:, m]) != 0] for m in range(3)])
    assert len(levels) > 10_000
    result = stats.kstest(levels, stats.uniform(loc=0.15, scale=0.85).cdf)
    assert result.pvalue > 1e-3


def test_motors_are_independent(hour: np.ndarray) -> None:
    switches = np.diff(hour, axis=0) != 0
    n = len(switches)
    p = HOUR.switch_probability
    for i, j in ((0, 1), (0, 2), (1, 2)):
        # Simultaneous switches of two motors: Poisson with mean n p^2 (~46 in an hour).
        both = int(np.sum(switches[:, i] & switches[:, j]))
        assert abs(both - n * p * p) < 4 * math.sqrt(n * p * p)
        # Levels are held ~78 samples, so the effective sample size is ~n / 156; 4 sd ~ 0.1.
        assert abs(np.corrcoef(hour[:, i], hour[:, j])[0, 1]) < 4 / math.sqrt(n / 156)


def test_same_seed_same_sequence_other_seed_differs() -> None:
    a = babbling_activations(np.random.default_rng(7), n_samples=5000)
    b = babbling_activations(np.random.default_rng(7), n_samples=5000)
    c = babbling_activations(np.random.default_rng(8), n_samples=5000)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


@pytest.mark.parametrize("n", [1, 2, 77, 1000])
def test_any_length(n: int) -> None:
    a = babbling_activations(np.random.default_rng(0), n_samples=n)
    assert a.shape == (n, 3)


def test_zero_length_raises() -> None:
    with pytest.raises(ValueError, match="n_samples"):
        babbling_activations(np.random.default_rng(0), n_samples=0)


def test_config_fields_are_used() -> None:
    cfg = BabblingConfig(duration_s=10.0, rate_hz=100.0, low=0.3, high=0.5, n_motors=2, mean_dwell_s=0.5)
    a = babbling_activations(np.random.default_rng(0), cfg)
    assert a.shape == (1000, 2)
    assert a.min() >= 0.3
    assert a.max() <= 0.5
    assert cfg.switch_probability == pytest.approx(1 / 50)


@pytest.mark.parametrize(
    ("field", "kwargs"),
    [
        ("duration_s", {"duration_s": 0.0}),
        ("rate_hz", {"rate_hz": -78.0}),
        ("mean_dwell_s", {"mean_dwell_s": float("nan")}),
        ("mean_dwell_s", {"mean_dwell_s": 0.001}),
        ("low, high", {"low": 0.9, "high": 0.2}),
        ("low, high", {"high": 1.5}),
        ("n_motors", {"n_motors": 0}),
    ],
)
def test_invalid_config_names_the_field(field: str, kwargs: dict[str, float]) -> None:
    with pytest.raises(ConfigError, match=f"^{field}:"):
        BabblingConfig(**kwargs)  # type: ignore[arg-type]
