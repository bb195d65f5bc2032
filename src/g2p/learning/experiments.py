"""The paper's experiments on any rig: the treadmill task (Fig 4) and tracking in the air (Fig 5).

Each experiment advances one attempt at a time (`next_attempt`, until `finished`), so that a ROS action
server can publish feedback and honour cancel between attempts; `run_treadmill`,
`refine_one_trajectory` and `generalization` drive them to the end in-process.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike

from g2p.inverse_map import FitReport
from g2p.learning.attempt import AttemptOutcome, TrackingError, run_attempt
from g2p.learning.learner import Learner
from g2p.learning.limit_cycle import LimitCycleConfig
from g2p.learning.search import FloatArray, Phase, RewardSearch, SearchConfig, SearchStep
from g2p.rig import ProgressCallback, Rig


@dataclass(frozen=True)
class AttemptReport:
    """One attempt of a treadmill run: what the rig did, what the search made of it, and the refinement.

    Attributes:
        step: the search's record of the attempt (its number, phase, sigma).
        outcome: what was asked, what happened, and the scores.
        best_reward_mm: best reward so far, this attempt included (mm).
        fit: the refinement that followed the attempt.
    """

    step: SearchStep
    outcome: AttemptOutcome
    best_reward_mm: float
    fit: FitReport | None

    @property
    def number(self) -> int:
        """Attempt number within the run (1-based; counts the attempts before a restore)."""
        return self.step.number

    @property
    def phase(self) -> Phase:
        """The phase the attempt belonged to."""
        return self.step.phase

    @property
    def sigma(self) -> float | None:
        """Standard deviation of the exploitation draw (None in exploration)."""
        return self.step.sigma


class TreadmillRun:
    """Exploration until the reward threshold, then exploitation: one `next_attempt` at a time.

    Args:
        learner: a learner whose map is fitted (after babbling).
        search: search parameters (threshold, attempt budgets, sigma schedule, feature bounds).
        cycle: limit-cycle parameters; its feature bounds must equal the search's.
    """

    def __init__(self, learner: Learner, search: SearchConfig, cycle: LimitCycleConfig) -> None:
        if (search.feature_low, search.feature_high) != (cycle.feature_low, cycle.feature_high):
            raise ValueError(
                "search and cycle feature bounds differ: "
                f"{(search.feature_low, search.feature_high)} vs {(cycle.feature_low, cycle.feature_high)}"
            )
        self.learner = learner
        self.search = RewardSearch(search)
        self.cycle = cycle
        self.reports: list[AttemptReport] = []
        """Reports of the attempts this object ran, in order (after a restore: only those since)."""
        self._rng = learner.streams.search
        self._pending: FloatArray | None = None

    @property
    def finished(self) -> bool:
        """Whether the search is done or failed."""
        return self.search.finished

    @property
    def rng(self) -> np.random.Generator:
        """The generator of the search's proposals (its `bit_generator.state` is what a checkpoint keeps)."""
        return self._rng

    @property
    def pending_features(self) -> FloatArray | None:
        """Features proposed for an attempt that failed, to be tried again next, shape (n_features,) (a copy).

        None when the last attempt completed (or none was tried yet).
        """
        return None if self._pending is None else self._pending.copy()

    @pending_features.setter
    def pending_features(self, features: ArrayLike | None) -> None:
        if features is None:
            self._pending = None
            return
        f = np.array(features, dtype=np.float64)
        if f.shape != (self.search.config.n_features,):
            raise ValueError(
                f"pending_features: expected shape ({self.search.config.n_features},), got {f.shape}"
            )
        self._pending = f

    def next_features(self) -> FloatArray:
        """The features the next attempt plays, shape (n_features,) (a copy).

        Proposed on the first call (drawing from the search's generator exactly as `next_attempt` would),
        the same on later calls until an attempt completes: announcing them first changes nothing.
        """
        if self._pending is None:
            self._pending = self.search.propose(self._rng)
        return self._pending.copy()

    def next_attempt(
        self, rig: Rig, progress: ProgressCallback | None = None, cancel: threading.Event | None = None
    ) -> AttemptReport:
        """Propose features, run them, tell the search, refine the map.

        Features are drawn once per attempt: when the rig fails (RigError, RigCancelled included) the
        search, the map, the dataset and every generator are as they were before the try, and the next
        call tries the same features again, so a retried run is the run that never failed.
        """
        features = self.next_features()
        outcome, fit = self.learner.attempt(rig, features, self.cycle, True, progress, cancel)
        self._pending = None
        told = self.search.tell(features, outcome.reward_mm)
        report = AttemptReport(told, outcome, self.search.best_reward_mm, fit)
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
        babbling_fit: the initial fit (None for a run resumed from a checkpoint).
    """

    reports: tuple[AttemptReport, ...]
    crossed_threshold: bool
    exploration_attempts: int
    exploitation_attempts: int
    best_features: np.ndarray
    best_reward_mm: float
    babbling_fit: FitReport | None


def treadmill_result(run: TreadmillRun, babbling_fit: FitReport | None) -> TreadmillResult:
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
    run = TreadmillRun(learner, search, cycle)
    while not run.finished:
        run.next_attempt(rig)
    return treadmill_result(run, fit)


@dataclass(frozen=True)
class TrackingReport:
    """One step of a free-movement experiment.

    Attributes:
        stage: "training" (an attempt, refined after it when the experiment says so) or "testing" (an
            unseen trajectory played with a fixed map: the babbling-only one or the refined one).
        number: step number within its stage (1-based).
        features: the trajectory's spoke lengths, shape (n_spokes,).
        tracking: the tracking error of the step.
        outcome: the attempt (training; None when testing).
        fit: the refinement that followed the attempt (None when not refined).
        babbling_map: testing: whether the babbling-only map played (else the refined one).
    """

    stage: str
    number: int
    features: np.ndarray
    tracking: TrackingError
    outcome: AttemptOutcome | None = None
    fit: FitReport | None = None
    babbling_map: bool = False


class TrajectoryRefinement:
    """Free movement in the air (paper Fig 5a): one trajectory, one `next_attempt` at a time.

    The trajectory is attempted with the babbling map, then refined on and attempted again `refinements`
    times.

    Args:
        learner: a learner whose map is fitted (after babbling).
        features: the trajectory's spoke lengths, shape (n_spokes,).
        cycle: limit-cycle parameters (air bounds).
        refinements: how many times the map is refined (paper: 5).
    """

    def __init__(
        self, learner: Learner, features: np.ndarray, cycle: LimitCycleConfig, refinements: int = 5
    ) -> None:
        self.learner = learner
        self.features = np.asarray(features, dtype=np.float64)
        self.cycle = cycle
        self.refinements = refinements
        self.outcomes: list[AttemptOutcome] = []

    @property
    def finished(self) -> bool:
        """Whether every attempt was played (refinements + 1)."""
        return len(self.outcomes) > self.refinements

    def next_attempt(
        self, rig: Rig, progress: ProgressCallback | None = None, cancel: threading.Event | None = None
    ) -> TrackingReport:
        """Play the trajectory once more and refine the map on it, except after the last attempt."""
        k = len(self.outcomes)
        outcome, fit = self.learner.attempt(
            rig, self.features, self.cycle, k < self.refinements, progress, cancel
        )
        self.outcomes.append(outcome)
        return TrackingReport("training", k + 1, self.features, outcome.tracking, outcome, fit)


class Experiment(Protocol):
    """An experiment stepped one attempt at a time: TreadmillRun, TrajectoryRefinement, Generalization."""

    cycle: LimitCycleConfig  # the limit-cycle parameters its attempts play

    @property
    def finished(self) -> bool:
        """Whether the experiment is over."""

    def next_attempt(
        self, rig: Rig, progress: ProgressCallback | None = None, cancel: threading.Event | None = None
    ) -> AttemptReport | TrackingReport:
        """Run the next step on the rig and report it."""


def refine_one_trajectory(
    learner: Learner, rig: Rig, features: np.ndarray, cycle: LimitCycleConfig, refinements: int = 5
) -> list[AttemptOutcome]:
    """`TrajectoryRefinement` in-process, to the end.

    Returns:
        refinements + 1 outcomes: the attempt with the babbling map, then one after each refinement.
    """
    experiment = TrajectoryRefinement(learner, features, cycle, refinements)
    while not experiment.finished:
        experiment.next_attempt(rig)
    return experiment.outcomes


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


class Generalization:
    """Generalization to unseen trajectories (paper Fig 5b), one `next_attempt` at a time.

    The map is refined on the training trajectories; then every test trajectory is tracked with the
    babbling-only map, then every one with the refined map, both fixed (in this order: each play advances
    the rig's state, e.g. the simulator's tick jitter).

    Args:
        learner: a learner whose map was fitted on babbling only.
        cycle: limit-cycle parameters (air bounds).
        train: training trajectories' features, shape (n_train, n_spokes) (paper: 30).
        test: unseen test trajectories' features, shape (n_test, n_spokes) (paper: 30).
    """

    def __init__(
        self, learner: Learner, cycle: LimitCycleConfig, train: np.ndarray, test: np.ndarray
    ) -> None:
        self.learner = learner
        self.cycle = cycle
        self.train = np.asarray(train, dtype=np.float64)
        self.test = np.asarray(test, dtype=np.float64)
        self._babbling_map = learner.frozen_map()
        self.trained = 0
        self.babbling_map_errors: list[TrackingError] = []
        self.refined_map_errors: list[TrackingError] = []

    @property
    def stage(self) -> str:
        """The next step's stage: "training" until every training trajectory was attempted, then "testing"."""
        return "training" if self.trained < len(self.train) else "testing"

    @property
    def finished(self) -> bool:
        """Whether every test trajectory was tracked with both maps."""
        return len(self.refined_map_errors) == len(self.test)

    def next_attempt(
        self, rig: Rig, progress: ProgressCallback | None = None, cancel: threading.Event | None = None
    ) -> TrackingReport:
        """The next training attempt (then a refinement), or the next test trajectory with the next map."""
        if self.stage == "training":
            features = self.train[self.trained]
            outcome, fit = self.learner.attempt(rig, features, self.cycle, True, progress, cancel)
            self.trained += 1
            return TrackingReport("training", self.trained, features, outcome.tracking, outcome, fit)
        babbling = len(self.babbling_map_errors) < len(self.test)
        errors = self.babbling_map_errors if babbling else self.refined_map_errors
        inverse_map = self._babbling_map if babbling else self.learner.inverse_map
        features = self.test[len(errors)]
        outcome = run_attempt(
            rig,
            inverse_map,
            features,
            self.cycle,
            self.learner.lead_ticks,
            progress,
            cancel,
            self.learner.config.closed_loop_feedback,
        )
        errors.append(outcome.tracking)
        return TrackingReport("testing", len(errors), features, outcome.tracking, babbling_map=babbling)

    def result(self) -> GeneralizationResult:
        """The test errors so far of both maps."""
        return GeneralizationResult(tuple(self.babbling_map_errors), tuple(self.refined_map_errors))


def random_features(rng: np.random.Generator, cycle: LimitCycleConfig, n: int) -> np.ndarray:
    """N feature vectors uniform in the cycle's bounds, shape (n, n_spokes)."""
    return rng.uniform(cycle.feature_low, cycle.feature_high, size=(n, cycle.n_spokes))


def generalization(
    learner: Learner, rig: Rig, cycle: LimitCycleConfig, train: np.ndarray, test: np.ndarray
) -> GeneralizationResult:
    """`Generalization` in-process, to the end."""
    experiment = Generalization(learner, cycle, train, test)
    while not experiment.finished:
        experiment.next_attempt(rig)
    return experiment.result()


__all__ = [
    "AttemptReport",
    "Generalization",
    "GeneralizationResult",
    "TrackingReport",
    "TrajectoryRefinement",
    "TreadmillResult",
    "TreadmillRun",
    "generalization",
    "random_features",
    "refine_one_trajectory",
    "run_treadmill",
    "treadmill_result",
]
