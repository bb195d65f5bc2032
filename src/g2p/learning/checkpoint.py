"""A treadmill run's state after attempt k, small enough to travel as one JSON string in a ROS event message.

A checkpoint holds what a run needs to continue exactly as if it had never stopped, except the training
data: the map's weights and normalization (exact float64), each seen sample's side of the train/validation
split (later refinements keep it), the state of every generator (babbling, map, search), the search's told
(features, reward) history (its state follows from it) and a proposal drawn for an attempt that failed.
The recordings come back separately (from the run's bag); `restore` rebuilds the dataset from them as the
learner built it, and the rest of the checkpoint (the search's phase, best, sigma and counts; each dataset
segment's label, size and digest) verifies that the restored run is the captured one.

JSON numbers are written with Python's shortest round-trip repr, so floats come back bit for bit; generator
states are numpy PCG64 state dicts (integers of up to 128 bits). Measured with the paper's settings on the
MuJoCo leg: 8.9 kB right after 5 minutes of babbling (the map ~4 kB, the split of 23,300 samples at 1 bit
each, base64), then about 0.55 kB per attempt of 20 cycles (its features, reward, segment and the split of
its ~1,200 samples): 11.6 kB after 5 attempts, about 70 kB at the search's limit of 115 attempts.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any

import jsonschema
import numpy as np
from numpy.typing import NDArray

from g2p.inverse_map import InverseMap, InverseMapFormatError
from g2p.learning.experiments import TreadmillRun
from g2p.learning.kinematics import TrainingPairs
from g2p.learning.learner import Learner, LearnerConfig
from g2p.learning.limit_cycle import LimitCycleConfig
from g2p.learning.search import FloatArray, Phase, RewardSearch, SearchConfig, SearchFinished
from g2p.learning.seeds import SeedStreams
from g2p.plant import Recording

FORMAT_VERSION = 1
"""Version of the checkpoint's JSON format; bump on any change of keys or meaning."""
_KIND = "g2p.treadmill_checkpoint"
RNG_NAMES = tuple(f.name for f in fields(SeedStreams) if f.name != "tracking")
"""The generators a checkpoint keeps: the run's streams (`SeedStreams`) but the free-movement experiments'."""
_DIGEST_HEX = (
    16  # a segment's digest: the first 64 bits of the sha256 of its pairs, enough to tell data apart
)


_COUNT = {"type": "integer", "minimum": 0}
_FEATURES = {"type": "array", "items": {"type": "number"}, "minItems": 1}
_NUMBER_OR_NULL = {"type": ["number", "null"]}


def _record(**properties: object) -> dict[str, object]:
    """The schema of an object with exactly these properties, all required."""
    return {
        "type": "object",
        "required": list(properties),
        "additionalProperties": False,
        "properties": properties,
    }


SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "G2P treadmill checkpoint",
    **_record(
        kind={"const": _KIND},
        format_version={"const": FORMAT_VERSION},
        attempt=_COUNT,
        refinements=_COUNT,
        inverse_map={"type": "object", "additionalProperties": {"$ref": "#/$defs/numbers"}},
        validation_mask=_record(n=_COUNT, packbits_base64={"type": "string"}),
        rng_states=_record(**{name: {"type": "object"} for name in RNG_NAMES}),
        search=_record(
            told={"type": "array", "items": _record(features=_FEATURES, reward_mm={"type": "number"})},
            phase={"enum": [p.value for p in Phase]},
            best_features={"anyOf": [_FEATURES, {"type": "null"}]},
            best_reward_mm=_NUMBER_OR_NULL,
            sigma=_NUMBER_OR_NULL,
            n_exploration=_COUNT,
            n_exploitation=_COUNT,
        ),
        pending_features={"anyOf": [_FEATURES, {"type": "null"}]},
        segments={
            "type": "array",
            "items": _record(
                label={"type": "string"},
                n_samples=_COUNT,
                digest={"type": "string", "pattern": f"^[0-9a-f]{{{_DIGEST_HEX}}}$"},
            ),
        },
    ),
    "$defs": {
        "numbers": {"type": "array", "items": {"anyOf": [{"type": "number"}, {"$ref": "#/$defs/numbers"}]}}
    },
}
"""The checkpoint's JSON format as a JSON Schema (2020-12); `Checkpoint.from_json` validates against it."""
_VALIDATOR = jsonschema.Draft202012Validator(SCHEMA)


class CheckpointError(ValueError):
    """A checkpoint is malformed, or the recordings or configuration given to restore it are not the run's."""


@dataclass(frozen=True, eq=False)
class SegmentDigest:
    """One segment of the learner's dataset, as far as a checkpoint needs to recognize it.

    Attributes:
        label: the segment's label ("babbling", "attempt 3", ...).
        n_samples: its training pairs.
        digest: the first 16 hex digits of the sha256 of its kinematics then activation bytes (float64).
    """

    label: str
    n_samples: int
    digest: str


@dataclass(frozen=True, eq=False)
class SearchSnapshot:
    """The reward search: what it was told, and what it concluded (to verify a replay).

    Attributes:
        told: every told attempt as (features (n_features,), reward (mm)), in order.
        phase: the phase after the last.
        best_features: features of the best attempt, shape (n_features,); None before the first.
        best_reward_mm: its reward (mm); -inf before the first attempt.
        sigma: standard deviation of the next exploitation draw; None unless exploiting.
        n_exploration: exploration attempts told.
        n_exploitation: exploitation attempts told.
    """

    told: tuple[tuple[FloatArray, float], ...]
    phase: Phase
    best_features: FloatArray | None
    best_reward_mm: float
    sigma: float | None
    n_exploration: int
    n_exploitation: int


@dataclass(frozen=True, eq=False)
class Checkpoint:
    """A treadmill run after attempt k (k = 0: right after the babbling fit), without its training data.

    Attributes:
        attempt: attempts completed by the run (k).
        refinements: refinements of the map since babbling (k, plus any made before the run started).
        inverse_map: the map's `to_arrays` (exact float64).
        validation_mask: which samples trained on so far are held out, shape (N,) bool, N = dataset size.
        rng_states: bit_generator state of each generator in RNG_NAMES (numpy PCG64 state dicts).
        search: the search's history and conclusions.
        pending_features: features drawn for an attempt that failed, to be tried next, shape
            (n_features,); None after a completed attempt.
        segments: the dataset's segments in order: the babbling chunks, then one per refinement.
    """

    attempt: int
    refinements: int
    inverse_map: Mapping[str, FloatArray]
    validation_mask: NDArray[np.bool_]
    rng_states: Mapping[str, Mapping[str, Any]]
    search: SearchSnapshot
    pending_features: FloatArray | None
    segments: tuple[SegmentDigest, ...]

    @property
    def n_babbling_segments(self) -> int:
        """Segments of the dataset that are babbling chunks (the first ones)."""
        return len(self.segments) - self.refinements

    def to_json(self) -> str:
        """The checkpoint as compact standard JSON (no NaN or infinity); `from_json` reads it back exactly."""
        s = self.search
        mask = self.validation_mask
        doc = {
            "kind": _KIND,
            "format_version": FORMAT_VERSION,
            "attempt": self.attempt,
            "refinements": self.refinements,
            "inverse_map": {name: a.tolist() for name, a in self.inverse_map.items()},
            "validation_mask": {
                "n": len(mask),
                "packbits_base64": base64.b64encode(np.packbits(mask).tobytes()).decode("ascii"),
            },
            "rng_states": {name: self.rng_states[name] for name in RNG_NAMES},
            "search": {
                "told": [{"features": f.tolist(), "reward_mm": r} for f, r in s.told],
                "phase": s.phase.value,
                "best_features": None if s.best_features is None else s.best_features.tolist(),
                "best_reward_mm": None if s.best_reward_mm == -math.inf else s.best_reward_mm,
                "sigma": s.sigma,
                "n_exploration": s.n_exploration,
                "n_exploitation": s.n_exploitation,
            },
            "pending_features": None if self.pending_features is None else self.pending_features.tolist(),
            "segments": [
                {"label": g.label, "n_samples": g.n_samples, "digest": g.digest} for g in self.segments
            ],
        }
        return json.dumps(doc, allow_nan=False, separators=(",", ":"))

    @classmethod
    def from_json(cls, text: str, source: str) -> Checkpoint:
        """Read a checkpoint written by `to_json`.

        The document is checked against `SCHEMA` (JSON Schema 2020-12, with the `jsonschema` library), then
        for what a schema cannot say: the map's names and shapes, the mask's size, the generators' states
        and the agreement of the parts.

        Args:
            text: the JSON text (standard JSON: NaN, Infinity and numbers beyond float64 are refused).
            source: where the text came from (e.g. a bag and event), for error messages.

        Raises:
            CheckpointError: not JSON, not a checkpoint, another format version, a missing key, a value of
                the wrong type or shape, or parts that contradict each other; the message names `source`
                and the key.
        """
        try:
            doc = json.loads(text, parse_constant=_refuse_constant, parse_float=_finite_float)
        except (json.JSONDecodeError, ValueError) as err:
            raise CheckpointError(f"{source}: not JSON: {err}") from err
        if not isinstance(doc, dict) or doc.get("kind") != _KIND:
            kind = doc.get("kind") if isinstance(doc, dict) else None
            raise CheckpointError(f"{source}: not a treadmill checkpoint (kind {kind!r}, expected {_KIND!r})")
        if doc.get("format_version") != FORMAT_VERSION:
            raise CheckpointError(
                f"{source}: format_version {doc.get('format_version')!r} is not supported "
                f"(expected {FORMAT_VERSION})"
            )
        error = jsonschema.exceptions.best_match(_VALIDATOR.iter_errors(doc))
        if error is not None:
            where = error.json_path.removeprefix("$").removeprefix(".") or "the document"
            raise CheckpointError(f"{source}: {where}: {error.message}")

        arrays = {
            name: _array(value, f"{source}: inverse_map.{name}") for name, value in doc["inverse_map"].items()
        }
        try:
            InverseMap.from_arrays(arrays, source=f"{source}: inverse_map")  # checks names and shapes
        except InverseMapFormatError as err:
            raise CheckpointError(str(err)) from err

        n_mask = doc["validation_mask"]["n"]
        try:
            packed = base64.b64decode(doc["validation_mask"]["packbits_base64"], validate=True)
        except binascii.Error as err:
            raise CheckpointError(f"{source}: validation_mask.packbits_base64 is not base64: {err}") from err
        if len(packed) != (n_mask + 7) // 8:
            raise CheckpointError(
                f"{source}: validation_mask holds {len(packed)} bytes, expected {(n_mask + 7) // 8} for "
                f"n = {n_mask}"
            )
        mask = np.unpackbits(np.frombuffer(packed, dtype=np.uint8), count=n_mask).astype(bool)

        states = doc["rng_states"]
        for name in RNG_NAMES:
            try:
                np.random.PCG64().state = states[name]
            except (TypeError, ValueError, KeyError) as err:
                raise CheckpointError(f"{source}: rng_states.{name} is not a PCG64 state: {err!r}") from err

        s = doc["search"]
        search = SearchSnapshot(
            told=tuple((np.array(t["features"], dtype=np.float64), float(t["reward_mm"])) for t in s["told"]),
            phase=Phase(s["phase"]),
            best_features=None
            if s["best_features"] is None
            else np.array(s["best_features"], dtype=np.float64),
            best_reward_mm=-math.inf if s["best_reward_mm"] is None else float(s["best_reward_mm"]),
            sigma=None if s["sigma"] is None else float(s["sigma"]),
            n_exploration=s["n_exploration"],
            n_exploitation=s["n_exploitation"],
        )
        if search.n_exploration + search.n_exploitation != len(search.told):
            raise CheckpointError(
                f"{source}: search counts {search.n_exploration} exploration + {search.n_exploitation} "
                f"exploitation attempts, but {len(search.told)} were told"
            )
        pending = (
            None if doc["pending_features"] is None else np.array(doc["pending_features"], dtype=np.float64)
        )
        n_features = {len(f) for f, _ in search.told}
        n_features.update(len(f) for f in (search.best_features, pending) if f is not None)
        if len(n_features) > 1:
            raise CheckpointError(f"{source}: feature vectors of different lengths {sorted(n_features)}")
        attempt, refinements = doc["attempt"], doc["refinements"]
        if attempt != len(search.told):
            raise CheckpointError(
                f"{source}: attempt is {attempt} but the search was told {len(search.told)} attempts"
            )

        segments = tuple(SegmentDigest(g["label"], g["n_samples"], g["digest"]) for g in doc["segments"])
        if len(segments) <= refinements:
            raise CheckpointError(
                f"{source}: {len(segments)} dataset segments cannot hold babbling and {refinements} "
                "refinements"
            )
        n_samples = sum(g.n_samples for g in segments)
        if n_mask != n_samples:
            raise CheckpointError(
                f"{source}: validation_mask covers {n_mask} samples, the segments hold {n_samples}"
            )
        return cls(attempt, refinements, arrays, mask, states, search, pending, segments)


def capture(run: TreadmillRun) -> Checkpoint:
    """The checkpoint of a run between attempts (or right after babbling, before its first attempt).

    Raises:
        CheckpointError: the learner's map is not fitted, or has no validation split (a loaded map).
    """
    learner, search = run.learner, run.search
    mask = learner.inverse_map.validation_mask
    if not learner.inverse_map.is_fitted or mask is None:
        raise CheckpointError("capture: the learner's map was not fitted on its dataset (babble first)")
    return Checkpoint(
        attempt=len(search.history),
        refinements=learner.refinements,
        inverse_map=learner.inverse_map.to_arrays(),
        validation_mask=mask,
        rng_states={
            "babbling": learner.babbling_rng.bit_generator.state,
            "inverse_map": learner.map_rng.bit_generator.state,
            "search": run.rng.bit_generator.state,
        },
        search=_search_snapshot(search),
        pending_features=run.pending_features,
        segments=tuple(_segment(label, pairs) for label, pairs in learner.dataset.segments),
    )


def restore(
    checkpoint: Checkpoint,
    babbling: Sequence[Recording],
    attempts: Sequence[Recording],
    learner_config: LearnerConfig,
    search: SearchConfig,
    cycle: LimitCycleConfig,
) -> TreadmillRun:
    """A fresh run in the checkpoint's state, its dataset rebuilt from the recordings; nothing is refitted.

    The restored run's `reports` start empty; its next attempt is numbered `checkpoint.attempt + 1`.

    Args:
        checkpoint: the run's checkpoint.
        babbling: the babbling recordings, one per chunk played, in order (`Learner.babbling_recordings`).
        attempts: the recording of every refinement since babbling, in order: for a run started right
            after babbling, its completed attempts' (`AttemptReport.outcome.recording`).
        learner_config: the run's learner configuration (preprocessing and training must be the run's).
        search: the run's search parameters.
        cycle: the run's limit-cycle parameters.

    Raises:
        CheckpointError: the recordings are not the run's (another number of them, segments of other sizes
            or contents), or the search replayed with `search` does not reach the checkpoint's state.
    """
    c = checkpoint
    if len(babbling) != c.n_babbling_segments:
        raise CheckpointError(
            f"restore: {len(babbling)} babbling recordings given, the checkpoint's dataset has "
            f"{c.n_babbling_segments} babbling segments"
        )
    if len(attempts) != c.refinements:
        raise CheckpointError(
            f"restore: {len(attempts)} attempt recordings given, the checkpoint was taken after "
            f"{c.refinements} refinements"
        )
    learner = Learner(learner_config)
    labels = [g.label for g in c.segments[c.n_babbling_segments :]]
    try:
        learner.load_data(babbling, list(zip(labels, attempts, strict=True)))
    except ValueError as err:
        raise CheckpointError(f"restore: the recordings cannot be preprocessed: {err}") from err
    for k, (expected, (label, pairs)) in enumerate(zip(c.segments, learner.dataset.segments, strict=True)):
        got = _segment(label, pairs)
        if got.n_samples != expected.n_samples:
            raise CheckpointError(
                f"restore: dataset segment {k} ({label!r}) has {got.n_samples} samples from its recording, "
                f"the checkpoint's has {expected.n_samples}"
            )
        if got.digest != expected.digest:
            raise CheckpointError(
                f"restore: dataset segment {k} ({label!r}) differs from the checkpoint's (digest "
                f"{got.digest}, expected {expected.digest}): not the recording it was made of"
            )
    learner.inverse_map = InverseMap.from_arrays(
        c.inverse_map, learner_config.inverse_map, "checkpoint", c.validation_mask
    )
    learner.babbling_rng.bit_generator.state = c.rng_states["babbling"]
    learner.map_rng.bit_generator.state = c.rng_states["inverse_map"]

    run = TreadmillRun(learner, search, cycle)
    run.rng.bit_generator.state = c.rng_states["search"]
    for k, (features, reward) in enumerate(c.search.told):
        try:
            run.search.tell(features, reward)
        except (ValueError, SearchFinished) as err:
            raise CheckpointError(
                f"restore: told attempt {k + 1} does not replay with this search: {err}"
            ) from err
    _verify_search(c.search, _search_snapshot(run.search))
    run.pending_features = c.pending_features
    return run


def _search_snapshot(search: RewardSearch) -> SearchSnapshot:
    return SearchSnapshot(
        told=tuple((np.array(a.features), a.reward_mm) for a in search.history),
        phase=search.phase,
        best_features=search.best_features,
        best_reward_mm=search.best_reward_mm,
        sigma=search.sigma,
        n_exploration=search.n_exploration,
        n_exploitation=search.n_exploitation,
    )


def _verify_search(expected: SearchSnapshot, replayed: SearchSnapshot) -> None:
    """Raise CheckpointError naming the first conclusion of the replayed search that differs."""
    want, got = _conclusions(expected), _conclusions(replayed)
    for name, value in want.items():
        if got[name] != value:
            raise CheckpointError(
                f"restore: the search replayed with this SearchConfig has {name} {got[name]}, the "
                f"checkpoint's {value}"
            )


def _conclusions(s: SearchSnapshot) -> dict[str, object]:
    """What a search concluded from its history, as plain values that compare exactly."""
    return {
        "phase": s.phase.value,
        "best_features": None if s.best_features is None else s.best_features.tolist(),
        "best_reward_mm": s.best_reward_mm,
        "sigma": s.sigma,
        "n_exploration": s.n_exploration,
        "n_exploitation": s.n_exploitation,
    }


def _segment(label: str, pairs: TrainingPairs) -> SegmentDigest:
    digest = hashlib.sha256()
    digest.update(np.ascontiguousarray(pairs.kinematics, dtype=np.float64).tobytes())
    digest.update(np.ascontiguousarray(pairs.activation, dtype=np.float64).tobytes())
    return SegmentDigest(label, len(pairs), digest.hexdigest()[:_DIGEST_HEX])


def _refuse_constant(name: str) -> None:
    raise ValueError(f"{name} is not a JSON number")


def _finite_float(text: str) -> float:
    """A JSON number as a float; one beyond float64's range (1e400) is refused rather than read as inf."""
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"{text} is out of the range of a float64")
    return value


def _array(value: Any, name: str) -> FloatArray:
    """A nested list of numbers (checked by the schema) as a float64 array; a ragged one is refused."""
    try:
        return np.array(value, dtype=np.float64)
    except ValueError as err:
        raise CheckpointError(f"{name} is not a rectangular array of numbers: {err}") from err


__all__ = [
    "FORMAT_VERSION",
    "RNG_NAMES",
    "SCHEMA",
    "Checkpoint",
    "CheckpointError",
    "SearchSnapshot",
    "SegmentDigest",
    "capture",
    "restore",
]
