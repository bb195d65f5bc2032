"""The paper's experiments on any rig: the treadmill task (Fig 4) and tracking in the air (Fig 5).

Each experiment advances one attempt at a time, so that a ROS action server can publish feedback and
honour cancel between attempts; the `run_*` functions drive them to the end in-process.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from g2p.attempt import AttemptOutcome, TrackingError, run_attempt
from g2p.inverse_map import FitReport, InverseMap
from g2p.learner import Learner
from g2p.limit_cycle import LimitCycleConfig
from g2p.rig import ProgressCallback, Rig
from g2p.search import Phase, RewardSearch, SearchConfig


@dataclass(frozen=True)
class AttemptReport:
    """One attempt of a treadmill run, with the search state after it.

    Attributes:
        number: attempt number within the run (1-based).
        phase: the phase the attempt belonged to.
        outcome: what was asked, what happened, and the scores.
        sigma: standard deviation of the exploitation draw (None in exploration).
        best_reward_mm: best reward so far, this attempt included (mm).
        fit: the refinement that followed the attempt.
    """

    number: int
    phase: Phase
    outcome: AttemptOutcome
    sigma: float | None
    best_reward_mm: float
    fit: FitReport | None


class TreadmillRun:
    """Exploration until the reward threshold, then exploitation: one `next_attempt` at a time.

    Args:
        learner: a learner whose map is fitted (after babbling).
        search: search parameters (threshold, attempt budgets, sigma schedule, feature bounds).
        cycle: limit-cycle parameters; its feature bounds must equal the search's.
        seed: seed of the search's proposals.
    """

    def __init__(self, learner: Learner, search: SearchConfig, cycle: LimitCycleConfig, seed: int) -> None:
        if (search.feature_low, search.feature_high) != (cycle.feature_low, cycle.feature_high):
            raise ValueError(
                "search and cycle feature bounds differ: "
                f"{(search.feature_low, search.feature_high)} vs {(cycle.feature_low, cycle.feature_high)}"
            )
        self.learner = learner
        self.search = RewardSearch(search)
        self.cycle = cycle
        self.reports: list[AttemptReport] = []
        self._rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(3)[2])

    @property
    def finished(self) -> bool:
        """Whether the search is done or failed."""
        return self.search.finished

    def next_attempt(
        self, rig: Rig, progress: ProgressCallback | None = None, cancel: threading.Event | None = None
    ) -> AttemptReport:
        """Propose features, run them, tell the search, refine the map.

        A cancelled attempt (RigCancelled) leaves the search and the map as they were.
        """
        features = self.search.propose(self._rng)
        outcome, fit = self.learner.attempt(rig, features, self.cycle, True, progress, cancel)
        told = self.search.tell(features, outcome.reward_mm)
        report = AttemptReport(
            len(self.reports) + 1, told.phase, outcome, told.sigma, self.search.best_reward_mm, fit
        )
        self.reports.append(report)
        return report


@dataclass(frozen=True)
class TreadmillResult:
    """A whole treadmill run.

    Attributes:
        reports: every attempt, in order.
        crossed_threshold: whether exploration crossed the threshold.
        exploration_attempts: attempts in exploration, the crossing one included.
        exploitation_attempts: attempts in exploitation.
        best_features: features of the best attempt, shape (10,).
        best_reward_mm: its reward (mm).
        babbling_fit: the initial fit.
    """

    reports: tuple[AttemptReport, ...]
    crossed_threshold: bool
    exploration_attempts: int
    exploitation_attempts: int
    best_features: np.ndarray
    best_reward_mm: float
    babbling_fit: FitReport


def treadmill_result(run: TreadmillRun, babbling_fit: FitReport) -> TreadmillResult:
    """Summarize a run (finished or stopped early)."""
    s = run.search
    best = s.best_features if s.best_features is not None else np.full(s.config.n_features, np.nan)
    crossed = s.phase in (Phase.EXPLOITATION, Phase.DONE)
    return TreadmillResult(
        tuple(run.reports), crossed, s.n_exploration, s.n_exploitation, best, s.best_reward_mm, babbling_fit
    )


def run_treadmill(
    learner: Learner, rig: Rig, search: SearchConfig, cycle: LimitCycleConfig
) -> TreadmillResult:
    """The treadmill task in-process: babble, fit, then attempts until the search ends (paper Fig 4)."""
    fit = learner.babble(rig)
    run = TreadmillRun(learner, search, cycle, learner.config.seed)
    while not run.finished:
        run.next_attempt(rig)
    return treadmill_result(run, fit)


def refine_one_trajectory(
    learner: Learner, rig: Rig, features: np.ndarray, cycle: LimitCycleConfig, refinements: int = 5
) -> list[AttemptOutcome]:
    """Free movement in the air (paper Fig 5a): one trajectory, attempted and refined `refinements` times.

    Returns:
        refinements + 1 outcomes: the attempt with the babbling map, then one after each refinement.
    """
    outcomes = []
    for k in range(refinements + 1):
        outcome, _ = learner.attempt(rig, features, cycle, refine=k < refinements)
        outcomes.append(outcome)
    return outcomes


@dataclass(frozen=True)
class GeneralizationResult:
    """Babbling-only vs refined map, both fixed, on unseen trajectories (paper Fig 5b).

    Attributes:
        babbling_map: tracking error of each test trajectory with the babbling-only map.
        refined_map: tracking error of each test trajectory with the map refined on the training set.
    """

    babbling_map: tuple[TrackingError, ...]
    refined_map: tuple[TrackingError, ...]

    @property
    def median_mse_reduction(self) -> float:
        """1 - median(refined MSE) / median(babbling MSE): the paper's 75.37%."""
        before = np.median([e.mse_deg2 for e in self.babbling_map])
        after = np.median([e.mse_deg2 for e in self.refined_map])
        return float(1.0 - after / before)

    @property
    def share_improved(self) -> float:
        """Share of test trajectories tracked better by the refined map: the paper's 96.7%."""
        return float(
            np.mean(
                [r.mse_deg2 < b.mse_deg2 for b, r in zip(self.babbling_map, self.refined_map, strict=True)]
            )
        )


def random_features(rng: np.random.Generator, cycle: LimitCycleConfig, n: int) -> np.ndarray:
    """N feature vectors uniform in the cycle's bounds, shape (n, n_spokes)."""
    return rng.uniform(cycle.feature_low, cycle.feature_high, size=(n, cycle.n_spokes))


def evaluate_fixed_map(
    inverse_map: InverseMap, rig: Rig, trajectories: np.ndarray, cycle: LimitCycleConfig, lead_ticks: int
) -> tuple[TrackingError, ...]:
    """Tracking error of a fixed map on each trajectory (no refinement); `lead_ticks` as in `plan_attempt`."""
    return tuple(run_attempt(rig, inverse_map, f, cycle, lead_ticks).tracking for f in trajectories)


def generalization(
    learner: Learner, rig: Rig, cycle: LimitCycleConfig, train: np.ndarray, test: np.ndarray
) -> GeneralizationResult:
    """Refine on `train` trajectories, then test the babbling-only and the refined map on `test`.

    Args:
        learner: a learner whose map was fitted on babbling only.
        rig: the rig (in the air).
        cycle: limit-cycle parameters (air bounds).
        train: training trajectories' features, shape (n_train, n_spokes) (paper: 30).
        test: unseen test trajectories' features, shape (n_test, n_spokes) (paper: 30).
    """
    babbling_map = learner.frozen_map()
    for f in train:
        learner.attempt(rig, f, cycle, refine=True)
    return GeneralizationResult(
        evaluate_fixed_map(babbling_map, rig, test, cycle, learner.lead_ticks),
        evaluate_fixed_map(learner.inverse_map, rig, test, cycle, learner.lead_ticks),
    )


__all__ = [
    "AttemptReport",
    "GeneralizationResult",
    "TreadmillResult",
    "TreadmillRun",
    "evaluate_fixed_map",
    "generalization",
    "random_features",
    "refine_one_trajectory",
    "run_treadmill",
    "treadmill_result",
]
