"""Reward search: convergence on a synthetic reward, sigma schedule, bounds, phase machine, seeding."""

from __future__ import annotations

import math

import numpy as np
import pytest

from g2p.learning.search import (
    Phase,
    RewardSearch,
    SearchConfig,
    SearchFinished,
    SearchStep,
    exploitation_sigma,
)
from g2p.validation import ConfigError

F_STAR = np.full(10, 0.575)


def quadratic_reward(f: np.ndarray) -> float:
    """400 mm at f*, falling 1000 mm per unit squared distance; about 6 % of uniform draws exceed 64 mm."""
    return float(400.0 - 1000.0 * np.sum((f - F_STAR) ** 2))


def run(search: RewardSearch, rng: np.random.Generator) -> list[SearchStep]:
    while not search.finished:
        f = search.propose(rng)
        search.tell(f, quadratic_reward(f))
    return list(search.history)


def test_converges_on_a_synthetic_reward() -> None:
    # P(a uniform draw crosses 64 mm) ~ 6 %, so a run fails (100 misses) with probability ~0.2 %; an
    # exploitation phase of 15 steps with sd ~ 0.05 improves with probability > 99 % (measured over 400
    # seeds). Over 20 seeds: all finish, at least 19 improve, and the median gain is well above zero.
    gains, crossings = [], []
    for seed in range(20):
        search = RewardSearch()
        history = run(search, np.random.default_rng(seed))
        assert search.phase is Phase.DONE
        explore = [a for a in history if a.phase is Phase.EXPLORATION]
        exploit = [a for a in history if a.phase is Phase.EXPLOITATION]
        assert explore[-1].reward_mm > 64.0
        assert all(a.reward_mm <= 64.0 for a in explore[:-1])
        assert len(exploit) == 15
        gains.append(search.best_reward_mm - explore[-1].reward_mm)
        crossings.append(len(explore))
        assert search.best_features is not None
        assert np.linalg.norm(search.best_features - F_STAR) <= np.linalg.norm(explore[-1].features - F_STAR)
    assert sum(g > 0 for g in gains) >= 19
    assert np.median(gains) > 50.0
    assert 5 <= np.median(crossings) <= 30  # expected ~1 / 0.06 ~ 16


@pytest.mark.parametrize(
    ("best", "sigma"),
    [
        (64.0, (600 - 64) / 9000),
        (0.0, 600 / 9000),
        (-300.0, 0.1),
        (330.0, 0.03),  # (600 - 330) / 9000 = 0.03 exactly
        (400.0, 0.03),  # the floor
        (600.0, 0.03),
        (10_000.0, 0.03),
    ],
)
def test_sigma_schedule(best: float, sigma: float) -> None:
    assert exploitation_sigma(best) == pytest.approx(sigma)


def test_sigma_follows_the_best_reward_while_exploiting() -> None:
    search = RewardSearch()
    assert search.sigma is None
    search.tell(np.full(10, 0.5), 100.0)
    assert search.phase is Phase.EXPLOITATION
    assert search.sigma == pytest.approx(500 / 9000)
    search.tell(np.full(10, 0.5), 90.0)  # worse: sigma unchanged
    assert search.sigma == pytest.approx(500 / 9000)
    result = search.tell(np.full(10, 0.6), 420.0)
    assert result.sigma == pytest.approx(500 / 9000)  # the sd that attempt was drawn with
    assert result.improved
    assert search.sigma == pytest.approx(0.03)


def test_exploitation_draws_around_the_best_with_sigma() -> None:
    search = RewardSearch()
    best = np.linspace(0.4, 0.7, 10)
    search.tell(best, 150.0)
    rng = np.random.default_rng(3)
    draws = np.array([search.propose(rng) for _ in range(4000)])
    sigma = (600 - 150) / 9000
    # Far from the bounds nothing is clipped: mean within 4 standard errors, sd within 5 %.
    assert np.all(np.abs(draws.mean(axis=0) - best) < 4 * sigma / math.sqrt(4000))
    np.testing.assert_allclose(draws.std(axis=0), sigma, rtol=0.05)


def test_bounds_are_respected() -> None:
    cfg = SearchConfig(sigma_ref_mm=10_000.0)  # sd ~ 1: most draws would leave the box without clipping
    search = RewardSearch(cfg)
    rng = np.random.default_rng(4)
    for _ in range(50):
        f = search.propose(rng)
        assert np.all((f >= 0.15) & (f <= 1.0))
        assert search.tell(f, 0.0).phase is Phase.EXPLORATION
    corner = np.array([0.15, 1.0] * 5)
    search.tell(corner, 100.0)
    draws = np.array([search.propose(rng) for _ in range(500)])
    assert np.all((draws >= 0.15) & (draws <= 1.0))
    assert np.any(draws == 0.15)
    assert np.any(draws == 1.0)


def test_in_air_bounds() -> None:
    search = RewardSearch(SearchConfig(feature_low=0.2, feature_high=0.8))
    f = np.array([search.propose(np.random.default_rng(i)) for i in range(200)])
    assert f.min() >= 0.2
    assert f.max() <= 0.8
    with pytest.raises(ValueError, match=r"features\[0\] = 0.9"):
        search.tell(np.full(10, 0.9), 1.0)


def test_fails_after_max_exploration_attempts() -> None:
    search = RewardSearch()
    rng = np.random.default_rng(5)
    for i in range(100):
        assert search.phase is Phase.EXPLORATION
        search.tell(search.propose(rng), 64.0)  # at the threshold is not above it
        assert search.n_exploration == i + 1
    assert search.phase is Phase.FAILED
    assert search.finished
    assert search.n_exploitation == 0
    with pytest.raises(SearchFinished, match="failed"):
        search.propose(rng)
    with pytest.raises(SearchFinished):
        search.tell(np.full(10, 0.5), 1000.0)


def test_done_after_exploitation_attempts_with_counts() -> None:
    search = RewardSearch(SearchConfig(exploitation_attempts=3, max_exploration_attempts=5))
    rng = np.random.default_rng(6)
    search.tell(search.propose(rng), 10.0)
    search.tell(search.propose(rng), 70.0)
    assert (search.phase, search.n_exploration, search.n_exploitation) == (Phase.EXPLOITATION, 2, 0)
    for i in range(3):
        result = search.tell(search.propose(rng), 60.0 + i)
        assert result.phase is Phase.EXPLOITATION
        assert not result.improved
    assert (search.phase, search.n_exploration, search.n_exploitation) == (Phase.DONE, 2, 3)
    assert search.best_reward_mm == 70.0
    assert [a.number for a in search.history] == [1, 2, 3, 4, 5]
    with pytest.raises(SearchFinished, match="done"):
        search.propose(rng)


def test_zero_exploitation_attempts_ends_at_the_crossing() -> None:
    search = RewardSearch(SearchConfig(exploitation_attempts=0))
    search.tell(np.full(10, 0.5), 65.0)
    assert search.phase is Phase.DONE


def test_same_seed_same_proposals() -> None:
    a = run(RewardSearch(), np.random.default_rng(11))
    b = run(RewardSearch(), np.random.default_rng(11))
    c = run(RewardSearch(), np.random.default_rng(12))
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.features, y.features)
    assert not np.array_equal(a[0].features, c[0].features)


def test_results_are_immutable_copies() -> None:
    search = RewardSearch()
    f = np.full(10, 0.5)
    result = search.tell(f, 1.0)
    f[0] = 0.9
    assert result.features[0] == 0.5
    with pytest.raises(ValueError, match="read-only"):
        result.features[0] = 0.7
    best = search.best_features
    assert best is not None
    best[0] = 0.9
    assert search.best_features is not None
    assert search.best_features[0] == 0.5


@pytest.mark.parametrize(
    ("features", "reward", "match"),
    [
        (np.full(9, 0.5), 1.0, r"expected shape \(10,\)"),
        (np.full(10, 0.5), math.nan, "reward_mm: must be finite"),
        (np.array([0.5] * 9 + [math.inf]), 1.0, r"features\[9\] = inf"),
    ],
)
def test_tell_rejects_bad_input(features: np.ndarray, reward: float, match: str) -> None:
    search = RewardSearch()
    with pytest.raises(ValueError, match=match):
        search.tell(features, reward)
    assert search.n_exploration == 0  # nothing was recorded


@pytest.mark.parametrize(
    ("field", "kwargs"),
    [
        ("n_features", {"n_features": 0}),
        ("feature_low, feature_high", {"feature_low": 1.0, "feature_high": 0.15}),
        ("threshold_mm", {"threshold_mm": math.nan}),
        ("max_exploration_attempts", {"max_exploration_attempts": 0}),
        ("exploitation_attempts", {"exploitation_attempts": -1}),
        ("sigma_min", {"sigma_min": 0.0}),
        ("sigma_ref_mm", {"sigma_ref_mm": math.inf}),
        ("sigma_scale_mm", {"sigma_scale_mm": -9000.0}),
    ],
)
def test_invalid_config_names_the_field(field: str, kwargs: dict[str, float]) -> None:
    with pytest.raises(ConfigError, match=f"^{field}:"):
        SearchConfig(**kwargs)  # type: ignore[arg-type]
