"""The learner's work on its rig, recorded: babbling, attempts, runs (new or resumed) and experiments.

The algorithm is the core's (g2p.learning.learner, g2p.learning.experiments); a session plays it on the
node's rig and announces every step on the run's record (RunPublisher), so that the bag bounds each
sequence the learner played and a run can be continued from its last checkpoint.
The node converts goals and results.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Any

import numpy as np

from g2p.bags.runs import new_run_id
from g2p.inverse_map import FitReport
from g2p.learning import run_events
from g2p.learning.attempt import AttemptOutcome
from g2p.learning.checkpoint import capture
from g2p.learning.experiments import (
    Experiment,
    Generalization,
    TrajectoryRefinement,
    TreadmillRun,
    random_features,
)
from g2p.learning.learner import Learner
from g2p.learning.limit_cycle import LimitCycleConfig
from g2p.learning.run_events import Event
from g2p.learning.search import SearchConfig
from g2p.plant import Recording
from g2p.rig import ProgressCallback, RetryingRig
from g2p_learner.config import LearnerNodeConfig
from g2p_learner.run_publisher import RunPublisher
from g2p_ros.params import config_as_dict


@dataclass(frozen=True)
class Step:
    """The next attempt of an experiment, as its attempt_start event announces it."""

    phase: str
    number: int
    features: np.ndarray | None = None


class LearningSession:
    """The node's learner on its rig, every step recorded.

    Args:
        config: the node's settings.
        rig: the rig, retried while it is lost.
        record: where the run's events and maps go.
        cancel: set to end the current goal (the rig drops to baseline within one tick).
        log: the node's info logger.

    Attributes:
        learner: the learner (replaced by the recorded one when a run is resumed).
        run_id: the current run's id.
        bag_path: where the run is recorded ("" unknown).
    """

    def __init__(
        self,
        config: LearnerNodeConfig,
        rig: RetryingRig,
        record: RunPublisher,
        cancel: threading.Event,
        log: Callable[[str], object],
    ) -> None:
        self.config = config
        self.rig = rig
        self.record = record
        self.cancel = cancel
        self._log = log
        self.learner = Learner(config.learner)
        self.run_id = config.run_id or new_run_id(datetime.now(timezone.utc), np.random.default_rng())
        self.bag_path = config.bag_path
        self._single_attempts = 0

    @property
    def control(self) -> str:
        """How attempts are played: "open" or "closed" loop."""
        return self.learner.config.control.value

    def adopt(self, recorded: tuple[str, str] | None) -> None:
        """With no run id of its own, the session's runs are the recorder's: its (id, bag)."""
        if recorded is None or self.config.run_id:
            return
        run_id, bag = recorded
        self.run_id = run_id or self.run_id
        self.bag_path = self.config.bag_path or bag

    def babble(self, duration_s: float | None, progress: Callable[[int, int], None]) -> FitReport:
        """Babble for `duration_s` (None: the configured duration) and fit the map; the map is recorded."""
        fit = self.learner.babble(_BabblingSegments(self), duration_s, progress, self.cancel)
        self.record.inverse_map(self.learner, fit)
        return fit

    def attempt(
        self,
        features: np.ndarray,
        cycle: LimitCycleConfig,
        refine: bool,
        progress: Callable[[int, int], None],
    ) -> tuple[AttemptOutcome, FitReport | None]:
        """One attempt outside a run (numbered from 1 in the session), announced and recorded."""
        self._single_attempts += 1
        number = self._single_attempts
        self.record.attempt_start("attempt", number, features, cycle, self.control)
        outcome, fit = self.learner.attempt(self.rig, features, cycle, refine, progress, self.cancel)
        self.record.attempt_end("attempt", number, outcome)
        if fit is not None:
            self.record.inverse_map(self.learner, fit)
        return outcome, fit

    def start_run(
        self, search: SearchConfig, dataset_bag: str, babbling_s: float, progress: Callable[[int, int], None]
    ) -> tuple[TreadmillRun, FitReport]:
        """A new run: babble for `babbling_s` (0: as configured) or fit on a bag's data; then the search."""
        self.record.event(
            Event.RUN_START,
            detail={
                "goal": {"dataset_bag": dataset_bag, "babbling_duration_s": babbling_s},
                run_events.SEARCH: config_as_dict(search),
            },
        )
        fit = self._fit_from_bag(dataset_bag) if dataset_bag else self.babble(babbling_s or None, progress)
        return TreadmillRun(self.learner, search, self.config.cycle), fit

    def resume(self, bag: str, config_topic: str) -> TreadmillRun:
        """The run recorded in `bag`, restored at its last checkpoint; the continuation keeps its id.

        Args:
            bag: the run's bag.
            config_topic: the topic the node's settings were recorded on.

        Raises:
            ValueError: the bag holds no run to continue, or this node's learner and cycle settings are not
                the recorded run's (the search's come from the bag).
        """
        from g2p.bags.resume import resume_run  # only runs reading a bag need the bag library

        mine = json.loads(json.dumps(config_as_dict(self.config)))  # as recorded: JSON types
        point, run = resume_run(bag, mine, self.config.learner, self.config.cycle, config_topic)
        self.learner = run.learner
        self.run_id = point.run_id
        self.record.event(
            Event.RUN_START,
            detail={
                run_events.SEARCH: point.search,
                "resumed_from": {"bag": str(point.bag), "attempt": point.checkpoint.attempt},
            },
        )
        self.record.inverse_map(self.learner, None)
        self._log(
            f"run {self.run_id} resumed from {bag} after attempt {point.checkpoint.attempt} "
            f"({run.search.phase.value}, best {run.search.best_reward_mm:.1f} mm)"
        )
        return run

    def checkpoint(self, run: TreadmillRun) -> None:
        """Record the run's state (g2p.learning.checkpoint): `learn --resume` continues from the last one."""
        checkpoint = capture(run)
        self.record.event(
            Event.CHECKPOINT,
            attempt=checkpoint.attempt,
            detail={run_events.CHECKPOINT: json.loads(checkpoint.to_json())},
        )

    def tracking_experiment(
        self, refine_one: bool, features: np.ndarray, refinements: int, train: int, test: int
    ) -> tuple[TrajectoryRefinement | Generalization, Callable[[], Step | None]]:
        """A free-movement experiment (paper Fig. 3), and what announces its next attempt.

        Args:
            refine_one: refine one trajectory (else: generalization to unseen ones).
            features: the trajectory to refine (empty: a random one).
            refinements: attempts refining it (0: 5).
            train: training trajectories (0: 30).
            test: test trajectories (0: 30).
        """
        cycle = self.config.air_cycle
        rng = self.learner.streams.tracking
        if refine_one:
            chosen = features if len(features) else random_features(rng, cycle, 1)[0]
            refinement = TrajectoryRefinement(self.learner, chosen, cycle, refinements or 5)
            return refinement, lambda: Step("tracking", len(refinement.outcomes) + 1, refinement.features)
        generalization = Generalization(
            self.learner,
            cycle,
            random_features(rng, cycle, train or 30),
            random_features(rng, cycle, test or 30),
        )

        def upcoming() -> Step | None:
            """A training attempt is announced and recorded as one; the test tracking is not."""
            if generalization.stage != "training":
                return None
            return Step("tracking", generalization.trained + 1, generalization.train[generalization.trained])

        return generalization, upcoming

    def run_steps(
        self,
        experiment: Experiment,
        upcoming: Callable[[], Step | None],
        done: Callable[[Any], None],
        check_cancel: Callable[[], None],
    ) -> None:
        """Step `experiment` to its end: check cancel, announce the attempt, play it, report, record the map.

        `upcoming` describes the next step (None: not an attempt of the run, e.g. a test trajectory, and
        not announced); `done` emits the step's end event and the goal's feedback; `check_cancel` raises
        RigCancelled when the goal is cancelled.
        """
        while not experiment.finished:
            check_cancel()
            step = upcoming()
            if step is not None:
                self.record.attempt_start(
                    step.phase, step.number, step.features, experiment.cycle, self.control
                )
            report = experiment.next_attempt(self.rig, cancel=self.cancel)
            done(report)
            if report.fit is not None:
                self.record.inverse_map(self.learner, report.fit)

    def _fit_from_bag(self, bag: str) -> FitReport:
        from g2p.bags.dataset import load_training_data  # only runs reading a bag need the bag library

        data = load_training_data(bag)
        fit = self.learner.fit_babbling(list(data.babbling))
        self.record.inverse_map(self.learner, fit)
        for k, recording in enumerate(data.attempts, start=1):
            fit = self.learner.refine_with(recording, f"attempt {k} from {bag}")
            self.record.inverse_map(self.learner, fit)
        self.record.event(
            Event.PHASE_END,
            phase="babbling",
            detail={"dataset_bag": bag, "samples": len(self.learner.dataset)},
        )
        return fit


class _BabblingSegments:
    """The session's rig while babbling: each sequence played is announced as a babbling segment.

    The events bound each segment's ticks in the recorded topics, so a map rebuilt from the bag sees
    the same segments the learner saw.
    """

    def __init__(self, session: LearningSession) -> None:
        self._session = session

    def reset(self) -> None:
        self._session.rig.reset()

    def play(
        self,
        activations: np.ndarray,
        progress: ProgressCallback | None = None,
        cancel: threading.Event | None = None,
    ) -> Recording:
        self._session.record.segment(Event.PHASE_START)
        recording = self._session.rig.play(activations, progress, cancel)
        self._session.record.segment(Event.PHASE_END, recording)
        return recording
