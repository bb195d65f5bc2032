"""Treadmill runs that fail and retry, or stop and resume from a checkpoint, on the MuJoCo leg: the same run.

Known answers: a run whose rig failed some plays, and a run restored from a checkpoint and its recordings,
give bit for bit the features, rewards and map weights of the run that never stopped. The uninterrupted
run is a twin on its own plant (the plant's clock and tick jitter run on across plays, so the twin's plant
is where the original's would have been).
"""

from __future__ import annotations

import threading
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from g2p.learning.babbling import BabblingConfig
from g2p.learning.checkpoint import Checkpoint, CheckpointError, capture, restore
from g2p.learning.experiments import TreadmillRun
from g2p.learning.learner import Learner, LearnerConfig
from g2p.learning.limit_cycle import LimitCycleConfig
from g2p.learning.search import Phase, SearchConfig
from g2p.plant import Recording
from g2p.rig import PlantRig, ProgressCallback, RigCancelled, RigError
from g2p.sim import MujocoLeg, MujocoLegConfig

CONFIG = LearnerConfig(seed=1, babbling_chunk_s=10.0, babbling=BabblingConfig(duration_s=20.0))
CYCLE = LimitCycleConfig.treadmill(n_cycles=3)
# With seed 1 one of the first few attempts crosses 12 mm (which one depends on the machine's floating
# point: torch picks its kernels by CPU), then 3 exploitation attempts.
SEARCH = SearchConfig(threshold_mm=12.0, exploitation_attempts=3)
# The most exploration attempts the tests wait for the threshold to be crossed.
CROSSING_LIMIT = 20


def babbled() -> tuple[TreadmillRun, PlantRig]:
    """A run right after babbling 20 s in two chunks, and its rig."""
    rig = PlantRig(MujocoLeg(MujocoLegConfig()))
    learner = Learner(CONFIG)
    learner.babble(rig)
    return TreadmillRun(learner, SEARCH, CYCLE), rig


class FailingRig:
    """A real rig whose given plays (counted from 1) raise RigError before the plant is touched."""

    def __init__(self, rig: PlantRig, failing_plays: set[int]) -> None:
        self.rig = rig
        self.failing_plays = failing_plays
        self.plays = 0

    def reset(self) -> None:
        self.rig.reset()

    def play(
        self,
        activations: np.ndarray,
        progress: ProgressCallback | None = None,
        cancel: threading.Event | None = None,
    ) -> Recording:
        self.plays += 1
        if self.plays in self.failing_plays:
            raise RigError(f"play {self.plays}: injected failure")
        return self.rig.play(activations, progress, cancel)


def state(run: TreadmillRun) -> dict[str, Any]:
    """Everything a run continues from, as values that compare exactly."""
    learner, search = run.learner, run.search
    kinematics, activation = learner.dataset.arrays()
    return {
        "map": {k: v.tolist() for k, v in learner.inverse_map.to_arrays().items()},
        "validation_mask": learner.inverse_map.validation_mask.tolist(),  # type: ignore[union-attr]
        "rng": [learner.babbling_rng.bit_generator.state, learner.map_rng.bit_generator.state],
        "search_rng": run.rng.bit_generator.state,
        "told": [(a.phase, a.features.tolist(), a.reward_mm, a.sigma) for a in search.history],
        "search": (search.phase, search.best_reward_mm, search.sigma, search.n_exploration),
        "best_features": None if search.best_features is None else search.best_features.tolist(),
        "pending": None if run.pending_features is None else run.pending_features.tolist(),
        "dataset": (kinematics.tobytes(), activation.tobytes()),
        "labels": [(label, len(p)) for label, p in learner.dataset.segments],
        "refinements": learner.refinements,
    }


def step(run: TreadmillRun, rig: PlantRig | FailingRig) -> tuple[Any, ...]:
    """One attempt: (number, phase, features, reward, sigma, refined, map weights after it)."""
    report = run.next_attempt(rig)
    weights = run.learner.inverse_map.to_arrays()
    return (
        report.number,
        report.phase,
        report.outcome.features.tolist(),
        report.outcome.reward_mm,
        report.sigma,
        report.fit is not None,
        weights["w_hidden"].tolist(),
        weights["w_out"].tolist(),
    )


def finish(run: TreadmillRun, rig: PlantRig) -> list[tuple[Any, ...]]:
    """`step` until the search ends."""
    out = []
    while not run.finished:
        out.append(step(run, rig))
    return out


def test_failed_plays_are_retried_with_the_same_features_and_change_nothing() -> None:
    run, rig = babbled()
    twin, twin_rig = babbled()
    failing = FailingRig(rig, failing_plays={2, 3, 5})  # attempt 2 fails twice, attempt 3 once
    retried, failures = [], 0
    while not run.finished:
        before = state(run)
        try:
            retried.append(step(run, failing))
        except RigError:
            failures += 1
            after = state(run)
            if before["pending"] is None:  # a first try: only the proposal was drawn, and is kept
                assert after["pending"] is not None
                for key in ("pending", "search_rng"):
                    after.pop(key), before.pop(key)
            assert after == before  # the failed try left no other trace; a retry draws nothing
    assert failures == 3
    assert retried == finish(twin, twin_rig)
    assert state(run) == state(twin)


def test_a_cancelled_attempt_is_tried_again_with_its_features() -> None:
    run, rig = babbled()
    run.next_attempt(rig)
    before = state(run)
    cancel = threading.Event()

    def progress(done: int, _total: int) -> None:
        if done >= 78:  # a second of the attempt was played on the plant
            cancel.set()

    with pytest.raises(RigCancelled):
        run.next_attempt(rig, progress, cancel)
    pending = run.pending_features
    assert pending is not None
    after = state(run)
    for key in ("pending", "search_rng"):
        after.pop(key), before.pop(key)
    assert after == before
    report = run.next_attempt(rig)
    np.testing.assert_array_equal(report.outcome.features, pending)
    assert report.number == 2 and run.pending_features is None


def recordings(run: TreadmillRun) -> tuple[list[Recording], list[Recording]]:
    """The run's babbling and attempt recordings, as a bag gives them back."""
    return list(run.learner.babbling_recordings), [r.outcome.recording for r in run.reports]


@pytest.mark.parametrize("checkpoint_phase", [Phase.EXPLORATION, Phase.EXPLOITATION])
def test_a_restored_run_continues_exactly_as_the_uninterrupted_one(checkpoint_phase: Phase) -> None:
    run, rig = babbled()
    twin, twin_rig = babbled()
    k = 0  # attempts before the checkpoint: none, or up to the first in exploitation
    while run.search.phase is not checkpoint_phase:
        assert k < CROSSING_LIMIT, f"no attempt of {CROSSING_LIMIT} crossed {SEARCH.threshold_mm} mm"
        assert step(run, rig) == step(twin, twin_rig)
        k += 1
    assert state(run) == state(twin)  # the premise: the twin is the same run
    text = capture(run).to_json()
    assert len(text) < 20_000
    restored = restore(Checkpoint.from_json(text, "test"), *recordings(run), CONFIG, SEARCH, CYCLE)
    assert restored is not run and restored.learner is not run.learner
    assert state(restored) == state(run)
    assert capture(restored).to_json() == text
    # The restored run goes on on the original's plant; the twin never stopped.
    assert restored.search.phase is checkpoint_phase
    continued, uninterrupted = finish(restored, rig), finish(twin, twin_rig)
    assert continued, "the restored run had nothing left to do"
    assert [c[0] for c in continued] == list(range(k + 1, k + len(continued) + 1))
    assert Phase.EXPLOITATION in {c[1] for c in continued}
    assert continued == uninterrupted
    assert state(restored) == state(twin)


def test_restore_names_the_recordings_or_search_that_do_not_match() -> None:
    run, rig = babbled()
    n = 0  # at least 3 attempts, the last in exploitation
    while n < 3 or run.search.phase is not Phase.EXPLOITATION:
        assert n < CROSSING_LIMIT, f"no attempt of {CROSSING_LIMIT} crossed {SEARCH.threshold_mm} mm"
        run.next_attempt(rig)
        n += 1
    checkpoint = Checkpoint.from_json(capture(run).to_json(), "test")
    babbling, attempts = recordings(run)
    with pytest.raises(CheckpointError, match=rf"{n - 1} attempt recordings given, .* after {n} refinements"):
        restore(checkpoint, babbling, attempts[:-1], CONFIG, SEARCH, CYCLE)
    with pytest.raises(CheckpointError, match=r"1 babbling recordings given, .* has 2 babbling segments"):
        restore(checkpoint, babbling[:1], attempts, CONFIG, SEARCH, CYCLE)
    nudged = replace(attempts[1], position_rad=attempts[1].position_rad + 1e-12)  # as many samples
    with pytest.raises(
        CheckpointError, match=r"segment 3 \('attempt 2'\) differs from the checkpoint's \(digest"
    ):
        restore(checkpoint, babbling, [attempts[0], nudged, *attempts[2:]], CONFIG, SEARCH, CYCLE)
    shortened = [attempts[0], attempts[1].slice(0, 200), *attempts[2:]]
    with pytest.raises(CheckpointError, match=r"segment 3 \('attempt 2'\) has \d+ samples .* has \d+"):
        restore(checkpoint, babbling, shortened, CONFIG, SEARCH, CYCLE)
    with pytest.raises(CheckpointError, match=r"phase exploration, the checkpoint's exploitation"):
        restore(checkpoint, babbling, attempts, CONFIG, replace(SEARCH, threshold_mm=100.0), CYCLE)
