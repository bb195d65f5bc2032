"""Motor babbling: pseudo-random stair-step activations that explore the plant's dynamics.

Each motor independently holds a level and, at every sample, switches with probability
1 / (mean_dwell_s * rate_hz) to a new level drawn uniformly from [low, high] (paper, Methods:
"a 1/fs time probability" and levels in [15%, 100%]). Dwell times are therefore geometric with a
mean of `mean_dwell_s`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from g2p.plant import NOMINAL_TICK_HZ
from g2p.safety import BASELINE_ACTIVATION
from g2p.validation import require, require_positive, require_range

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class BabblingConfig:
    """Parameters of a babbling session (defaults: the paper's).

    Attributes:
        duration_s: session length (s); 5 min in the paper.
        rate_hz: sample (rig tick) rate at which activations are served (Hz).
        mean_dwell_s: mean time a motor holds a level (s); a motor switches with probability 1 / (mean_dwell_s
            * rate_hz) at each sample.
        low: lowest activation level (dimensionless); the 15% baseline tension.
        high: highest activation level (dimensionless).
        n_motors: number of motors (M0..M2).
    """

    duration_s: float = 300.0
    rate_hz: float = NOMINAL_TICK_HZ
    mean_dwell_s: float = 1.0
    low: float = BASELINE_ACTIVATION
    high: float = 1.0
    n_motors: int = 3

    def __post_init__(self) -> None:
        require_positive(self.duration_s, "duration_s")
        require_positive(self.rate_hz, "rate_hz")
        require_positive(self.mean_dwell_s, "mean_dwell_s")
        require(
            self.mean_dwell_s * self.rate_hz >= 1.0,
            "mean_dwell_s",
            f"must be at least one sample ({1.0 / self.rate_hz} s), got {self.mean_dwell_s}",
        )
        require_range(self.low, self.high, "low, high", 0.0, 1.0)
        require(self.n_motors >= 1, "n_motors", f"must be >= 1, got {self.n_motors}")

    @property
    def n_samples(self) -> int:
        """Samples in a session: round(duration_s * rate_hz) (23,400 by default)."""
        return round(self.duration_s * self.rate_hz)

    @property
    def switch_probability(self) -> float:
        """Probability that a motor switches level at a given sample."""
        return 1.0 / (self.mean_dwell_s * self.rate_hz)


def babbling_activations(
    rng: np.random.Generator, config: BabblingConfig | None = None, n_samples: int | None = None
) -> FloatArray:
    """Draw a babbling activation sequence.

    Args:
        rng: the only source of randomness; the same generator state gives the same sequence.
        config: session parameters; the defaults when None.
        n_samples: sequence length, overriding `config.n_samples` (any length >= 1).

    Returns:
        Activations, shape (n_samples, n_motors), one row per sample, in [low, high].

    Raises:
        ValueError: n_samples < 1.
    """
    cfg = config or BabblingConfig()
    n = cfg.n_samples if n_samples is None else n_samples
    if n < 1:
        raise ValueError(f"n_samples: must be >= 1, got {n}")
    switches = rng.random((n, cfg.n_motors)) < cfg.switch_probability
    switches[0] = True  # every motor starts on a freshly drawn level
    levels = rng.uniform(cfg.low, cfg.high, size=(n, cfg.n_motors))
    # Index of the most recent switch at or before each sample, per motor (forward fill).
    last_switch = np.maximum.accumulate(np.where(switches, np.arange(n)[:, None], 0), axis=0)
    return np.take_along_axis(levels, last_switch, axis=0)
