"""The reward search over limit-cycle features, as ask/tell: `propose(rng)`, run the attempt, `tell(reward)`.

Exploration draws features uniformly within the bounds until an attempt's reward exceeds the threshold
(64 mm), or fails after a maximum number of attempts (100). Exploitation then draws from a Gaussian centred
on the best features so far, clipped to the bounds, with a standard deviation that shrinks as the best reward
grows, sd = max(sigma_min, (sigma_ref_mm - best_mm) / sigma_scale_mm) (the authors' code), for 15 attempts.

The search holds no loop and does no I/O, so an action server can run one attempt per step, publish feedback
and honour a cancel between attempts. Its state follows from the sequence of told (features, reward) pairs.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from g2p.learning.limit_cycle import TREADMILL_FEATURE_BOUNDS
from g2p.validation import require, require_positive, require_range

FloatArray = NDArray[np.float64]


class Phase(str, enum.Enum):
    """Where the search is."""

    EXPLORATION = "exploration"
    """Uniform random features until a reward exceeds the threshold."""
    EXPLOITATION = "exploitation"
    """Gaussian steps around the best features so far."""
    DONE = "done"
    """All exploitation attempts were made."""
    FAILED = "failed"
    """No reward exceeded the threshold within the exploration budget."""


class SearchFinished(RuntimeError):
    """`propose` or `tell` was called after the search ended (phase done or failed)."""


@dataclass(frozen=True)
class SearchConfig:
    """Reward-search parameters (defaults: the paper's and the authors' code).

    Attributes:
        n_features: length of the feature vector (limit-cycle spokes).
        feature_low: smallest feature value (feature units; treadmill preset; 0.2 in the air).
        feature_high: largest feature value (feature units; treadmill preset; 0.8 in the air).
        threshold_mm: reward an exploration attempt must exceed to start exploitation (mm of belt travel).
        max_exploration_attempts: exploration attempts before the search fails.
        exploitation_attempts: exploitation attempts before the search is done.
        sigma_min: floor of the exploitation standard deviation (feature units).
        sigma_ref_mm: best reward at which the schedule (sigma_ref_mm - best) / sigma_scale_mm reaches 0 (mm).
        sigma_scale_mm: reward per unit of standard deviation in the schedule (mm).
    """

    n_features: int = 10
    feature_low: float = TREADMILL_FEATURE_BOUNDS[0]
    feature_high: float = TREADMILL_FEATURE_BOUNDS[1]
    threshold_mm: float = 64.0
    max_exploration_attempts: int = 100
    exploitation_attempts: int = 15
    sigma_min: float = 0.03
    sigma_ref_mm: float = 600.0
    sigma_scale_mm: float = 9000.0

    def __post_init__(self) -> None:
        require(self.n_features >= 1, "n_features", f"must be >= 1, got {self.n_features}")
        require_range(self.feature_low, self.feature_high, "feature_low, feature_high")
        require(math.isfinite(self.threshold_mm), "threshold_mm", f"must be finite, got {self.threshold_mm}")
        require(
            self.max_exploration_attempts >= 1,
            "max_exploration_attempts",
            f"must be >= 1, got {self.max_exploration_attempts}",
        )
        require(
            self.exploitation_attempts >= 0,
            "exploitation_attempts",
            f"must be >= 0, got {self.exploitation_attempts}",
        )
        require_positive(self.sigma_min, "sigma_min")
        require(math.isfinite(self.sigma_ref_mm), "sigma_ref_mm", f"must be finite, got {self.sigma_ref_mm}")
        require_positive(self.sigma_scale_mm, "sigma_scale_mm")


def exploitation_sigma(best_reward_mm: float, config: SearchConfig | None = None) -> float:
    """Standard deviation of exploitation steps for a best reward: max(sigma_min, (ref - best) / scale)."""
    cfg = config or SearchConfig()
    return max(cfg.sigma_min, (cfg.sigma_ref_mm - best_reward_mm) / cfg.sigma_scale_mm)


@dataclass(frozen=True)
class SearchStep:
    """One told attempt.

    Attributes:
        number: attempt number over the whole search, from 1.
        phase: the phase the attempt belonged to (exploration or exploitation).
        features: the features run, shape (n_features,), read-only.
        reward_mm: its reward (mm of belt travel, + backward).
        sigma: the standard deviation the exploitation draw used (None in exploration).
        improved: whether it set a new best reward.
    """

    number: int
    phase: Phase
    features: FloatArray
    reward_mm: float
    sigma: float | None
    improved: bool


class RewardSearch:
    """Two-phase random search over limit-cycle features, driven one attempt at a time.

    Args:
        config: search parameters; the defaults when None.
    """

    def __init__(self, config: SearchConfig | None = None) -> None:
        self.config = config or SearchConfig()
        self._phase = Phase.EXPLORATION
        self._history: list[SearchStep] = []
        self._n_exploration = 0
        self._n_exploitation = 0
        self._best_features: FloatArray | None = None
        self._best_reward = -math.inf

    @property
    def phase(self) -> Phase:
        """The current phase."""
        return self._phase

    @property
    def finished(self) -> bool:
        """Whether the search ended (done or failed)."""
        return self._phase in (Phase.DONE, Phase.FAILED)

    @property
    def n_exploration(self) -> int:
        """Exploration attempts told so far."""
        return self._n_exploration

    @property
    def n_exploitation(self) -> int:
        """Exploitation attempts told so far."""
        return self._n_exploitation

    @property
    def best_features(self) -> FloatArray | None:
        """Features of the best attempt so far (a copy), None before the first."""
        return None if self._best_features is None else self._best_features.copy()

    @property
    def best_reward_mm(self) -> float:
        """Best reward so far (mm); -inf before the first attempt."""
        return self._best_reward

    @property
    def sigma(self) -> float | None:
        """Standard deviation of the next exploitation draw; None unless exploiting."""
        if self._phase is not Phase.EXPLOITATION:
            return None
        return exploitation_sigma(self._best_reward, self.config)

    @property
    def history(self) -> tuple[SearchStep, ...]:
        """Every told attempt, in order."""
        return tuple(self._history)

    def propose(self, rng: np.random.Generator) -> FloatArray:
        """Features for the next attempt.

        Args:
            rng: the only source of randomness (the same seed and tells give the same proposals).

        Returns:
            Features, shape (n_features,), within [feature_low, feature_high].

        Raises:
            SearchFinished: the search is done or failed.
        """
        cfg = self.config
        if self._phase is Phase.EXPLORATION:
            return rng.uniform(cfg.feature_low, cfg.feature_high, size=cfg.n_features)
        if self._phase is Phase.EXPLOITATION:
            assert self._best_features is not None  # set by the attempt that started exploitation
            step = rng.normal(0.0, exploitation_sigma(self._best_reward, cfg), size=cfg.n_features)
            return np.clip(self._best_features + step, cfg.feature_low, cfg.feature_high)
        raise SearchFinished(f"the search is {self._phase.value}; nothing more to propose")

    def tell(self, features: ArrayLike, reward_mm: float) -> SearchStep:
        """Record an attempt's reward and advance the phase.

        Args:
            features: the features that were run, shape (n_features,), within the bounds.
            reward_mm: the attempt's reward (mm of belt travel, + backward), finite.

        Returns:
            The attempt as recorded.

        Raises:
            ValueError: features of the wrong shape, non-finite or out of bounds, or a non-finite reward.
            SearchFinished: the search is done or failed.
        """
        if self.finished:
            raise SearchFinished(f"the search is {self._phase.value}; no attempt can be told")
        f = self._check_features(features)
        reward = float(reward_mm)
        if not math.isfinite(reward):
            raise ValueError(f"reward_mm: must be finite, got {reward_mm!r}")
        phase, sigma = self._phase, self.sigma
        improved = reward > self._best_reward
        if improved:
            self._best_reward, self._best_features = reward, f
        cfg = self.config
        if phase is Phase.EXPLORATION:
            self._n_exploration += 1
            if reward > cfg.threshold_mm:
                self._phase = Phase.EXPLOITATION if cfg.exploitation_attempts > 0 else Phase.DONE
            elif self._n_exploration >= cfg.max_exploration_attempts:
                self._phase = Phase.FAILED
        else:
            self._n_exploitation += 1
            if self._n_exploitation >= cfg.exploitation_attempts:
                self._phase = Phase.DONE
        f.flags.writeable = False
        result = SearchStep(len(self._history) + 1, phase, f, reward, sigma, improved)
        self._history.append(result)
        return result

    def _check_features(self, features: ArrayLike) -> FloatArray:
        cfg = self.config
        f = np.array(features, dtype=np.float64)  # a copy: the caller's array stays theirs
        if f.shape != (cfg.n_features,):
            raise ValueError(f"features: expected shape ({cfg.n_features},), got {f.shape}")
        for k, value in enumerate(f):
            if not (math.isfinite(value) and cfg.feature_low <= value <= cfg.feature_high):
                raise ValueError(
                    f"features[{k}] = {value} is not a finite value in "
                    f"[{cfg.feature_low}, {cfg.feature_high}]"
                )
        return f
