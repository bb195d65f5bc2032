"""The G2P learner's memory: every (kinematics, activation) pair it has seen, and the inverse map.

Babbling fits the map; every attempt, good or bad, adds its data (minus the transition from rest) and
refines the map from its current weights on all data so far (paper, Fig 3), or, as a variant, on the
babbling and the most recent attempts only.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from g2p.inverse_map import FitCancelled, FitReport, InverseMap, InverseMapConfig
from g2p.learning.attempt import AttemptOutcome, run_attempt
from g2p.learning.babbling import BabblingConfig, babbling_activations
from g2p.learning.kinematics import PreprocessConfig, TrainingPairs, recording_pairs
from g2p.learning.limit_cycle import LimitCycleConfig
from g2p.learning.seeds import seed_streams
from g2p.plant import Recording, concatenate
from g2p.rig import ProgressCallback, Rig
from g2p.rig.closed_loop import ControlMode, FeedbackConfig
from g2p.validation import ConfigError, require, require_positive


@dataclass(frozen=True)
class LearnerConfig:
    """How the learner babbles, preprocesses and fits.

    Attributes:
        seed: seed of every random choice the learner makes (babbling, weights, splits).
        babbling_chunk_s: length of each sequence sent to the rig while babbling (s); progress is reported
            and cancel honoured between chunks.
        babbling: the babbling session.
        preprocess: resampling and differentiation.
        inverse_map: network and training.
        control: how attempts are played: open loop (the paper's G2P) or closed loop.
        feedback: the closed loop's settings (used in closed loop only).
        refine_recent_attempts: the attempts whose data refines the map beside the babbling: the most
            recent N; 0: every attempt so far (the paper's).
    """

    seed: int = 0
    babbling_chunk_s: float = 30.0
    babbling: BabblingConfig = field(default_factory=BabblingConfig)
    preprocess: PreprocessConfig = field(default_factory=PreprocessConfig)
    inverse_map: InverseMapConfig = field(default_factory=InverseMapConfig)
    control: ControlMode = ControlMode.OPEN
    feedback: FeedbackConfig = field(default_factory=FeedbackConfig)
    refine_recent_attempts: int = 0

    def __post_init__(self) -> None:
        require_positive(self.babbling_chunk_s, "babbling_chunk_s")
        require(
            self.refine_recent_attempts >= 0,
            "refine_recent_attempts",
            f"must be >= 0, got {self.refine_recent_attempts}",
        )
        try:
            object.__setattr__(self, "control", ControlMode(self.control))
        except ValueError as err:
            raise ConfigError(
                f"control: must be one of {[m.value for m in ControlMode]}, got {self.control!r}"
            ) from err

    @property
    def closed_loop_feedback(self) -> FeedbackConfig | None:
        """The feedback settings attempts are played with; None in open loop."""
        return self.feedback if self.control is ControlMode.CLOSED else None


BABBLING = "babbling"
"""The label of the dataset's babbling segments."""


@dataclass
class Dataset:
    """Training pairs accumulated over a run, in the order they were collected."""

    segments: list[tuple[str, TrainingPairs]] = field(default_factory=list)

    def add(self, label: str, pairs: TrainingPairs) -> None:
        """Append a segment (e.g. "babbling", "attempt 3")."""
        self.segments.append((label, pairs))

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """All kinematics (K, 6) and activations (K, 3) so far."""
        return (
            np.concatenate([p.kinematics for _, p in self.segments]),
            np.concatenate([p.activation for _, p in self.segments]),
        )

    def recent(self, attempts: int) -> np.ndarray:
        """Which of the K samples of `arrays` are babbling's or the last `attempts` others', shape (K,) bool.

        Args:
            attempts: how many of the latest non-babbling segments to keep; 0: all of them.
        """
        others = [i for i, (label, _) in enumerate(self.segments) if label != BABBLING]
        kept = set(others[-attempts:] if attempts else others)
        return np.concatenate(
            [np.full(len(p), label == BABBLING or i in kept) for i, (label, p) in enumerate(self.segments)]
        )

    def __len__(self) -> int:
        return sum(len(p) for _, p in self.segments)


class Learner:
    """Babbles, fits, runs attempts and refines; holds the dataset and the inverse map.

    Args:
        config: learner settings.
    """

    def __init__(self, config: LearnerConfig | None = None) -> None:
        self.config = config or LearnerConfig()
        self.streams = seed_streams(self.config.seed)
        """The run's random streams, from its one seed: babbling and the map's here, the search's in
        `TreadmillRun`, the free-movement experiments' in the tracking experiments."""
        self.inverse_map = InverseMap(self.config.inverse_map)
        self.dataset = Dataset()
        self.refinements = 0
        self.babbling_recordings: tuple[Recording, ...] = ()
        """The babbling recordings the map was fitted on, one per chunk played, in order."""
        self.babbling_recording: Recording | None = None
        """The same, end to end (None before babbling)."""

    @property
    def babbling_rng(self) -> np.random.Generator:
        """The babbling activations' generator (its `bit_generator.state` is what a checkpoint keeps)."""
        return self.streams.babbling

    @property
    def map_rng(self) -> np.random.Generator:
        """The map's weights' and splits' generator (its `bit_generator.state` is what a checkpoint keeps)."""
        return self.streams.inverse_map

    @property
    def lead_ticks(self) -> int:
        """Ticks each activation is played ahead of the kinematics it is for (the map's command lead)."""
        return self.config.preprocess.command_lead_ticks

    def babble(
        self,
        rig: Rig,
        duration_s: float | None = None,
        progress: ProgressCallback | None = None,
        cancel: threading.Event | None = None,
    ) -> FitReport:
        """Babble on the rig from rest, then fit the map on the babbling data (from fresh weights).

        Args:
            rig: the rig.
            duration_s: babbling length (s); the config's when None.
            progress: called with (ticks done, ticks total).
            cancel: when set, babbling stops and RigCancelled is raised (nothing is fitted).
        """
        cfg = self.config
        n = cfg.babbling.n_samples if duration_s is None else round(duration_s * cfg.babbling.rate_hz)
        activations = babbling_activations(self.streams.babbling, cfg.babbling, n)
        chunk = max(1, round(cfg.babbling_chunk_s * cfg.babbling.rate_hz))
        if progress is not None:
            progress(0, n)  # babbling has begun, before the rig's first report
        rig.reset()
        recordings = []
        for start in range(0, n, chunk):

            def chunk_progress(done: int, _total: int, start: int = start) -> None:
                if progress is not None:
                    progress(start + done, n)

            recordings.append(rig.play(activations[start : start + chunk], chunk_progress, cancel))
        if progress is not None:
            progress(n, n)
        return self.fit_babbling(recordings, cancel)

    def fit_babbling(self, recordings: list[Recording], cancel: threading.Event | None = None) -> FitReport:
        """Replace the dataset by babbling recordings (each a contiguous segment) and fit the map afresh.

        Raises:
            FitCancelled: `cancel` was set during the fit (the data is kept, the map is not fitted).
        """
        self.load_data(recordings, [])
        return self.inverse_map.fit(*self.dataset.arrays(), self.streams.inverse_map, cancel)

    def load_data(self, babbling: Sequence[Recording], attempts: Sequence[tuple[str, Recording]]) -> None:
        """Rebuild the dataset as `fit_babbling` then `refine_with` build it, without fitting anything.

        For resuming a run whose map is restored separately (`g2p.learning.checkpoint`).

        Args:
            babbling: the babbling recordings, one per contiguous segment, in order.
            attempts: (label, recording) of every refinement since babbling, in order.
        """
        self.dataset = Dataset()
        for rec in babbling:
            self.dataset.add(BABBLING, recording_pairs(rec, self.config.preprocess))
        self.babbling_recordings = tuple(babbling)
        self.babbling_recording = concatenate(babbling)
        for label, rec in attempts:
            self.dataset.add(label, self._attempt_pairs(rec))
        self.refinements = len(attempts)

    def attempt(
        self,
        rig: Rig,
        features: np.ndarray,
        cycle: LimitCycleConfig,
        refine: bool = True,
        progress: ProgressCallback | None = None,
        cancel: threading.Event | None = None,
    ) -> tuple[AttemptOutcome, FitReport | None]:
        """Run one attempt and, unless told not to, refine the map with its data.

        Returns:
            The attempt's outcome, and the refinement's report (None when not refined).
        """
        outcome = run_attempt(
            rig,
            self.inverse_map,
            features,
            cycle,
            self.lead_ticks,
            progress,
            cancel,
            self.config.closed_loop_feedback,
        )
        return outcome, (
            self.refine_with(outcome.recording, f"attempt {self.refinements + 1}", cancel) if refine else None
        )

    def refine_with(
        self, recording: Recording, label: str, cancel: threading.Event | None = None
    ) -> FitReport:
        """Add an attempt's data (without its transition from rest) and refine the map.

        The refinement trains on all data, or with `refine_recent_attempts` on the babbling and the recent
        attempts.

        Raises:
            FitCancelled: `cancel` was set during the refinement; the data and the map are as before.
        """
        self.dataset.add(label, self._attempt_pairs(recording))
        try:
            recent = self.config.refine_recent_attempts
            rows = self.dataset.recent(recent) if recent else None
            report = self.inverse_map.refine(*self.dataset.arrays(), self.streams.inverse_map, cancel, rows)
        except FitCancelled:
            self.dataset.segments.pop()
            raise
        self.refinements += 1
        return report

    def _attempt_pairs(self, recording: Recording) -> TrainingPairs:
        return recording_pairs(recording, self.config.preprocess, self.config.preprocess.transition_fraction)

    def frozen_map(self) -> InverseMap:
        """A copy of the current map, unaffected by later refinements."""
        return InverseMap.from_arrays(self.inverse_map.to_arrays(), self.inverse_map.config)
