"""The inverse map's settings and the names its training shares with it (no torch, no numpy state).

`g2p.inverse_map` (the map) and `g2p.inverse_map.training` (torch) both import this module; neither imports
the other at import time.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from g2p.safety import BASELINE_ACTIVATION
from g2p.validation import ConfigError, require, require_positive, require_range

N_INPUTS = 6
N_OUTPUTS = 3


class Optimizer(str, enum.Enum):
    """Training algorithm."""

    LM = "lm"
    """Levenberg-Marquardt on the full batch (MATLAB trainlm); one iteration = one accepted step."""
    LBFGS = "lbfgs"
    """Full-batch L-BFGS with a strong-Wolfe line search; one iteration = one L-BFGS iteration."""
    ADAM = "adam"
    """Adam on shuffled minibatches; one iteration = one epoch."""


class Normalization(str, enum.Enum):
    """Column-wise normalization of the inputs and the targets."""

    MINMAX = "minmax"
    """Map each column's [min, max] to [-1, 1] (the authors' mapminmax)."""
    ZSCORE = "zscore"
    """Subtract each column's mean and divide by its standard deviation."""


class StopReason(str, enum.Enum):
    """Why training stopped."""

    VALIDATION = "validation"
    """The validation error did not improve for `patience` consecutive iterations."""
    MAX_ITERATIONS = "max_iterations"
    """The iteration budget ran out."""
    CONVERGED = "converged"
    """No step lowers the training error any more (LM damping at its maximum, or L-BFGS converged)."""


@dataclass(frozen=True)
class InverseMapConfig:
    """Network and training parameters (defaults: the paper's network, MATLAB trainlm's training).

    Attributes:
        n_hidden: hidden tanh units.
        activation_low: lowest activation `predict` returns (dimensionless): the baseline tension.
        activation_high: highest activation `predict` returns (dimensionless).
        normalization: input and target normalization, fixed at the initial fit.
        validation_fraction: share of the samples held out for early stopping (MATLAB's default split: 15%).
        optimizer: training algorithm (chosen by benchmarks/bench_inverse_map.py).
        max_iterations_fit: iteration budget of the initial fit. MATLAB's default is 1000 epochs; LM stops on
            validation after 100-280 iterations on 5 min of babbling, and 300 keeps the fit of 23,400 samples
            under 5 s on one core.
        max_iterations_refine: iteration budget of one refinement (keeps a refinement on ~70,000 samples under
            1 s on one core).
        patience: consecutive iterations without a better validation error before stopping (MATLAB's
            max_fail).
        lm_mu: initial Levenberg-Marquardt damping (MATLAB's mu).
        lm_mu_decrease: damping factor after an accepted step (MATLAB's mu_dec).
        lm_mu_increase: damping factor after a rejected step (MATLAB's mu_inc).
        lm_mu_max: damping at which LM gives up (MATLAB's mu_max).
        lbfgs_history: L-BFGS memory (pairs of steps).
        adam_learning_rate: adam step size (normalized units).
        adam_batch_size: adam minibatch size (samples).
        num_threads: torch intra-op threads while training; 0 leaves torch's setting alone. One thread is the
            default: on a shared 2-core machine, two OpenMP threads sometimes stall for seconds
            (docs/ALGORITHM.md).
    """

    n_hidden: int = 15
    activation_low: float = BASELINE_ACTIVATION
    activation_high: float = 1.0
    normalization: Normalization = Normalization.MINMAX
    validation_fraction: float = 0.15
    optimizer: Optimizer = Optimizer.LM
    max_iterations_fit: int = 300
    max_iterations_refine: int = 10
    patience: int = 6
    lm_mu: float = 1e-3
    lm_mu_decrease: float = 0.1
    lm_mu_increase: float = 10.0
    lm_mu_max: float = 1e10
    lbfgs_history: int = 20
    adam_learning_rate: float = 1e-2
    adam_batch_size: int = 1024
    num_threads: int = 1

    def __post_init__(self) -> None:
        for name, kind in (("normalization", Normalization), ("optimizer", Optimizer)):
            value = getattr(self, name)
            try:
                object.__setattr__(self, name, kind(value))
            except ValueError as err:
                raise ConfigError(f"{name}: must be one of {[m.value for m in kind]}, got {value!r}") from err
        require(self.n_hidden >= 1, "n_hidden", f"must be >= 1, got {self.n_hidden}")
        require_range(self.activation_low, self.activation_high, "activation_low, activation_high", 0.0, 1.0)
        require(
            0.0 < self.validation_fraction < 0.5,
            "validation_fraction",
            f"must be in (0, 0.5), got {self.validation_fraction}",
        )
        require(
            self.max_iterations_fit >= 1, "max_iterations_fit", f"must be >= 1, got {self.max_iterations_fit}"
        )
        require(
            self.max_iterations_refine >= 1,
            "max_iterations_refine",
            f"must be >= 1, got {self.max_iterations_refine}",
        )
        require(self.patience >= 1, "patience", f"must be >= 1, got {self.patience}")
        require_positive(self.lm_mu, "lm_mu")
        require(
            0.0 < self.lm_mu_decrease < 1.0, "lm_mu_decrease", f"must be in (0, 1), got {self.lm_mu_decrease}"
        )
        require(self.lm_mu_increase > 1.0, "lm_mu_increase", f"must be > 1, got {self.lm_mu_increase}")
        require(
            self.lm_mu_max > self.lm_mu,
            "lm_mu_max",
            f"must exceed lm_mu ({self.lm_mu}), got {self.lm_mu_max}",
        )
        require(self.lbfgs_history >= 1, "lbfgs_history", f"must be >= 1, got {self.lbfgs_history}")
        require_positive(self.adam_learning_rate, "adam_learning_rate")
        require(self.adam_batch_size >= 1, "adam_batch_size", f"must be >= 1, got {self.adam_batch_size}")
        require(self.num_threads >= 0, "num_threads", f"must be >= 0, got {self.num_threads}")


class FitCancelled(RuntimeError):
    """A fit or refinement was cancelled (Ctrl-C, a goal's cancel); the map is as it was before it.

    Its random generator has moved on: a run cancelled here continues from its last checkpoint.
    """
