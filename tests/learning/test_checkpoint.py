"""Checkpoints of a treadmill run without a plant: exact JSON round trips, restores, and bad input.

The run's data are recordings of a synthetic leg (smooth angles, stair-step activations, jittered stamps);
its attempts are refinements on such recordings told to the search with made-up rewards, as
`TreadmillRun.next_attempt` does after a play.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

import jsonschema
import numpy as np
import pytest

from g2p.learning.checkpoint import SCHEMA, Checkpoint, CheckpointError, capture, restore
from g2p.learning.experiments import TreadmillRun
from g2p.learning.learner import Learner, LearnerConfig
from g2p.learning.limit_cycle import LimitCycleConfig
from g2p.learning.search import SearchConfig
from g2p.plant import Recording

CONFIG = LearnerConfig(seed=4)
CYCLE = LimitCycleConfig.treadmill()
SEARCH = SearchConfig(threshold_mm=10.0, exploitation_attempts=4)
REWARDS_MM = [3.0, 25.0, 12.5]  # the second crosses the threshold


def synthetic_recording(rng: np.random.Generator, duration_s: float, t0_s: float) -> Recording:
    """Ticks at about 78 Hz from t0_s: angles a sum of slow sines, activations a stair-step."""
    n = round(duration_s * 78.0)
    t = t0_s + np.cumsum(1.0 / 78.0 + rng.uniform(-0.0008, 0.0008, n))
    f, phase = rng.uniform(0.3, 2.0, (3, 2)), rng.uniform(0.0, 2 * np.pi, (3, 2))
    q = np.sum(0.3 * np.sin(2 * np.pi * f[:, None, :] * t[None, :, None] + phase[:, None, :]), axis=0)
    steps = rng.uniform(0.15, 1.0, (n // 39 + 1, 3))
    zeros1, zeros3 = np.zeros(n), np.zeros((n, 3))
    return Recording(
        t, np.repeat(steps, 39, axis=0)[:n], q, np.zeros((n, 2)), zeros1, zeros1, zeros3, zeros3, zeros3
    )


def run_after(k: int) -> tuple[TreadmillRun, list[Recording], list[Recording]]:
    """A run after babbling on two recordings and k attempts; its babbling and attempt recordings."""
    rng = np.random.default_rng(11)
    babbling = [synthetic_recording(rng, 10.0, 0.0), synthetic_recording(rng, 10.0, 10.0)]
    learner = Learner(CONFIG)
    learner.fit_babbling(babbling)
    run = TreadmillRun(learner, SEARCH, CYCLE)
    attempts = []
    for reward in REWARDS_MM[:k]:
        attempts.append(synthetic_recording(rng, 4.0, 30.0 + 5.0 * len(attempts)))
        attempt(run, attempts[-1], reward)
    return run, babbling, attempts


def attempt(run: TreadmillRun, recording: Recording, reward_mm: float) -> None:
    """What next_attempt does after a complete play: refine on the recording, tell the reward."""
    features = run.search.propose(run.rng)
    run.learner.refine_with(recording, f"attempt {run.learner.refinements + 1}")
    run.search.tell(features, reward_mm)


def state(run: TreadmillRun) -> dict[str, Any]:
    """Everything a run continues from, as values that compare exactly."""
    learner, search = run.learner, run.search
    mask = learner.inverse_map.validation_mask
    assert mask is not None
    return {
        "map": {k: v.tolist() for k, v in learner.inverse_map.to_arrays().items()},
        "validation_mask": mask.tolist(),
        "rng": [g.bit_generator.state for g in (learner.babbling_rng, learner.map_rng, run.rng)],
        "told": [(a.phase, a.features.tolist(), a.reward_mm, a.sigma) for a in search.history],
        "search": (search.phase, search.best_reward_mm, search.sigma, search.n_exploration),
        "pending": None if run.pending_features is None else run.pending_features.tolist(),
        "dataset": tuple(a.tobytes() for a in learner.dataset.arrays()),
        "labels": [(label, len(p)) for label, p in learner.dataset.segments],
        "refinements": learner.refinements,
    }


@pytest.mark.parametrize("k", [0, 3])
def test_a_checkpoint_round_trips_through_json_and_restores_the_run_exactly(k: int) -> None:
    run, babbling, attempts = run_after(k)
    checkpoint = capture(run)
    text = checkpoint.to_json()
    back = Checkpoint.from_json(text, "test")
    assert back.to_json() == text
    assert back.attempt == k and back.refinements == k and back.pending_features is None
    assert [g.label for g in back.segments] == ["babbling", "babbling"] + [
        f"attempt {i + 1}" for i in range(k)
    ]
    for name, a in checkpoint.inverse_map.items():
        np.testing.assert_array_equal(back.inverse_map[name], a, strict=True)
    np.testing.assert_array_equal(back.validation_mask, checkpoint.validation_mask, strict=True)
    assert (back.search.best_features is None) == (k == 0)
    restored = restore(back, babbling, attempts, CONFIG, SEARCH, CYCLE)
    assert state(restored) == state(run)
    # One more attempt on each: the same refinement, the same next proposal.
    more = synthetic_recording(np.random.default_rng(99), 4.0, 60.0)
    attempt(run, more, 7.0)
    attempt(restored, more, 7.0)
    assert state(restored) == state(run)


def test_a_pending_proposal_is_kept_and_tried_next() -> None:
    run, babbling, attempts = run_after(1)
    run.pending_features = run.search.propose(run.rng)  # as next_attempt leaves it when the rig fails
    restored = restore(
        Checkpoint.from_json(capture(run).to_json(), "test"), babbling, attempts, CONFIG, SEARCH, CYCLE
    )
    assert state(restored) == state(run)
    pending = restored.pending_features
    assert pending is not None
    np.testing.assert_array_equal(pending, run.pending_features, strict=True)


def test_a_checkpoint_stays_small() -> None:
    run, _, _ = run_after(3)
    text = capture(run).to_json()
    # 20 s of babbling and 3 short attempts: the map (~4 kB) dominates; see the module docstring for runs.
    assert len(text) < 12_000


def test_capture_needs_a_fitted_map() -> None:
    run = TreadmillRun(Learner(CONFIG), SEARCH, CYCLE)
    with pytest.raises(CheckpointError, match="not fitted"):
        capture(run)


def _set(path: str, value: Any) -> Callable[[dict[str, Any]], None]:
    """An edit of a checkpoint document: the value at a dotted path (list indices as numbers)."""

    def edit(doc: dict[str, Any]) -> None:
        *parents, last = path.split(".")
        node: Any = doc
        for key in parents:
            node = node[int(key)] if isinstance(node, list) else node[key]
        if value is _DELETE:
            del node[last]
        elif isinstance(node, list):
            node[int(last)] = value
        else:
            node[last] = value

    return edit


_DELETE = object()


@pytest.fixture(scope="module")
def checkpoint_json() -> str:
    """The JSON checkpoint of a run after 3 attempts (2 in exploration)."""
    run, _, _ = run_after(3)
    return capture(run).to_json()


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (_set("kind", "g2p.inverse_map"), r"not a treadmill checkpoint \(kind 'g2p.inverse_map'"),
        (_set("format_version", 2), "format_version 2 is not supported"),
        (_set("rng_states", _DELETE), "the document: 'rng_states' is a required property"),
        (_set("search.told.1.reward_mm", _DELETE), r"search.told\[1\]: 'reward_mm' is a required property"),
        (_set("attempt", True), "attempt: True is not of type 'integer'"),
        (_set("attempt", 2), "attempt is 2 but the search was told 3 attempts"),
        (_set("inverse_map.w_out", [[0.0] * 15] * 2), r"w_out has shape \(2, 15\), expected \(3, 15\)"),
        (_set("inverse_map.b_out", [0.0, "x", 1.0]), r"inverse_map.b_out\[1\]: 'x' is not valid under any"),
        (_set("validation_mask.n", 5), r"validation_mask holds \d+ bytes, expected 1 for n = 5"),
        (_set("validation_mask.packbits_base64", "@@@"), "validation_mask.packbits_base64 is not base64"),
        (_set("rng_states.search.bit_generator", "MT19937"), "rng_states.search is not a PCG64 state"),
        (_set("search.told.0.features", [0.5] * 9), r"feature vectors of different lengths \[9, 10\]"),
        (_set("search.phase", "walking"), r"search.phase: 'walking' is not one of \['exploration'"),
        (_set("search.best_reward_mm", float("inf")), "not JSON: Infinity is not a JSON number"),
        (_set("search.n_exploitation", 5), "search counts 2 exploration \\+ 5 exploitation attempts, but 3"),
        (_set("segments.0.n_samples", 10), r"validation_mask covers \d+ samples, the segments hold \d+"),
        (_set("segments.4.digest", "xyz"), r"segments\[4\].digest: 'xyz' does not match"),
        (_set("refinements", 5), "5 dataset segments cannot hold babbling and 5 refinements"),
    ],
)
def test_bad_checkpoints_are_refused_with_the_source_and_key(
    checkpoint_json: str, edit: Callable[[dict[str, Any]], None], message: str
) -> None:
    doc = json.loads(checkpoint_json)
    edit(doc)
    with pytest.raises(CheckpointError, match=f"^bag.mcap event 7: .*{message}"):
        Checkpoint.from_json(json.dumps(doc), "bag.mcap event 7")


def test_text_that_is_not_json_is_refused() -> None:
    with pytest.raises(CheckpointError, match=r"^event 3: not JSON"):
        Checkpoint.from_json('{"kind": ', "event 3")


def test_a_number_beyond_float64_is_refused_rather_than_read_as_infinity(checkpoint_json: str) -> None:
    doc = json.loads(checkpoint_json)
    doc["search"]["best_reward_mm"] = 12345.5
    text = json.dumps(doc).replace("12345.5", "1e400")
    with pytest.raises(CheckpointError, match=r"^event 3: not JSON: 1e400 is out of the range of a float64"):
        Checkpoint.from_json(text, "event 3")


def test_the_schema_is_a_valid_json_schema() -> None:
    jsonschema.Draft202012Validator.check_schema(SCHEMA)
