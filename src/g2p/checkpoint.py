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
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from g2p.experiments import TreadmillRun
from g2p.inverse_map import InverseMap, InverseMapFormatError
from g2p.kinematics import TrainingPairs
from g2p.learner import Learner, LearnerConfig
from g2p.limit_cycle import LimitCycleConfig
from g2p.plant import Recording
from g2p.search import FloatArray, Phase, RewardSearch, SearchConfig, SearchFinished

FORMAT_VERSION = 1
"""Version of the checkpoint's JSON format; bump on any change of keys or meaning."""
_KIND = "g2p.treadmill_checkpoint"
RNG_NAMES = ("babbling", "inverse_map", "search")
"""The generators a checkpoint keeps: the learner's babbling and map streams, the run's search stream."""
_DIGEST_HEX = (
    16  # a segment's digest: the first 64 bits of the sha256 of its pairs, enough to tell data apart
)


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

        Args:
            text: the JSON text.
            source: where the text came from (e.g. a bag and event), for error messages.

        Raises:
            CheckpointError: not JSON, not a checkpoint, another format version, a missing key, a value of
                the wrong type or shape, or parts that contradict each other; the message names `source`
                and the key.
        """
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as err:
            raise CheckpointError(f"{source}: not JSON: {err}") from err
        r = _Reader(source)
        if not isinstance(doc, dict) or doc.get("kind") != _KIND:
            kind = doc.get("kind") if isinstance(doc, dict) else None
            raise CheckpointError(f"{source}: not a treadmill checkpoint (kind {kind!r}, expected {_KIND!r})")
        version = r.get(doc, "format_version", int)
        if version != FORMAT_VERSION:
            raise CheckpointError(
                f"{source}: format_version {version} is not supported (expected {FORMAT_VERSION})"
            )
        attempt = r.count(doc, "attempt")
        refinements = r.count(doc, "refinements")

        maps = r.get(doc, "inverse_map", dict)
        arrays = {str(name): r.floats(value, f"inverse_map.{name}") for name, value in maps.items()}
        try:
            InverseMap.from_arrays(arrays, source=f"{source}: inverse_map")  # checks names and shapes
        except InverseMapFormatError as err:
            raise CheckpointError(str(err)) from err

        mask_doc = r.get(doc, "validation_mask", dict)
        n_mask = r.count(mask_doc, "n", "validation_mask.")
        try:
            packed = base64.b64decode(
                r.get(mask_doc, "packbits_base64", str, "validation_mask."), validate=True
            )
        except binascii.Error as err:
            raise CheckpointError(f"{source}: validation_mask.packbits_base64 is not base64: {err}") from err
        if len(packed) != (n_mask + 7) // 8:
            raise CheckpointError(
                f"{source}: validation_mask holds {len(packed)} bytes, expected {(n_mask + 7) // 8} for "
                f"n = {n_mask}"
            )
        mask = np.unpackbits(np.frombuffer(packed, dtype=np.uint8), count=n_mask).astype(bool)

        states = r.get(doc, "rng_states", dict)
        if set(states) != set(RNG_NAMES):
            raise CheckpointError(f"{source}: rng_states has {sorted(states)}, expected {sorted(RNG_NAMES)}")
        for name in RNG_NAMES:
            try:
                np.random.PCG64().state = states[name]
            except (TypeError, ValueError, KeyError) as err:
                raise CheckpointError(f"{source}: rng_states.{name} is not a PCG64 state: {err!r}") from err

        search = r.search(r.get(doc, "search", dict))
        n_features = {len(f) for f, _ in search.told}
        pending_doc = r.get(doc, "pending_features", (list, type(None)))
        pending = None if pending_doc is None else r.floats(pending_doc, "pending_features", 1)
        n_features.update(len(f) for f in (search.best_features, pending) if f is not None)
        if len(n_features) > 1:
            raise CheckpointError(f"{source}: feature vectors of different lengths {sorted(n_features)}")
        if attempt != len(search.told):
            raise CheckpointError(
                f"{source}: attempt is {attempt} but the search was told {len(search.told)} attempts"
            )

        segments = tuple(r.segment(g, k) for k, g in enumerate(r.get(doc, "segments", list)))
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

    run = TreadmillRun(learner, search, cycle, learner_config.seed)
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


class _Reader:
    """Typed access to a parsed checkpoint document, raising CheckpointError that names the source and key."""

    def __init__(self, source: str) -> None:
        self.source = source

    def get(self, doc: Mapping[str, Any], key: str, kind: type | tuple[type, ...], where: str = "") -> Any:
        """doc[key], which must be of `kind` (a bool is not an int here)."""
        if key not in doc:
            raise CheckpointError(f"{self.source}: {where}{key} is missing")
        value = doc[key]
        kinds = kind if isinstance(kind, tuple) else (kind,)
        if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):
            names = " or ".join("null" if k is type(None) else k.__name__ for k in kinds)
            raise CheckpointError(f"{self.source}: {where}{key} must be {names}, got {value!r:.80}")
        return value

    def count(self, doc: Mapping[str, Any], key: str, where: str = "") -> int:
        """doc[key], an integer >= 0."""
        value: int = self.get(doc, key, int, where)
        if value < 0:
            raise CheckpointError(f"{self.source}: {where}{key} must be >= 0, got {value}")
        return value

    def number(self, doc: Mapping[str, Any], key: str, where: str) -> float | None:
        """doc[key], a finite number or null."""
        value = self.get(doc, key, (int, float, type(None)), where)
        if value is not None and not math.isfinite(value):
            raise CheckpointError(f"{self.source}: {where}{key} must be finite, got {value}")
        return None if value is None else float(value)

    def floats(self, value: Any, name: str, ndim: int | None = None) -> FloatArray:
        """A nested list of finite numbers as a float64 array (of `ndim` dimensions when given)."""
        try:
            a = np.array(value, dtype=np.float64)
        except (TypeError, ValueError) as err:
            raise CheckpointError(f"{self.source}: {name} is not an array of numbers: {err}") from err
        if ndim is not None and a.ndim != ndim:
            raise CheckpointError(f"{self.source}: {name} has shape {a.shape}, expected {ndim} dimension(s)")
        if not np.all(np.isfinite(a)):
            raise CheckpointError(f"{self.source}: {name} has non-finite values")
        return a

    def search(self, doc: Mapping[str, Any]) -> SearchSnapshot:
        told = []
        for k, attempt in enumerate(self.get(doc, "told", list, "search.")):
            where = f"search.told[{k}]."
            if not isinstance(attempt, dict):
                raise CheckpointError(f"{self.source}: {where[:-1]} must be an object, got {attempt!r:.80}")
            features = self.floats(self.get(attempt, "features", list, where), f"{where}features", 1)
            reward = self.number(attempt, "reward_mm", where)
            if reward is None:
                raise CheckpointError(f"{self.source}: {where}reward_mm must be a number, got null")
            told.append((features, reward))
        phase_name = self.get(doc, "phase", str, "search.")
        try:
            phase = Phase(phase_name)
        except ValueError as err:
            raise CheckpointError(
                f"{self.source}: search.phase must be one of {[p.value for p in Phase]}, got {phase_name!r}"
            ) from err
        best_doc = self.get(doc, "best_features", (list, type(None)), "search.")
        best = None if best_doc is None else self.floats(best_doc, "search.best_features", 1)
        best_reward = self.number(doc, "best_reward_mm", "search.")
        n_exploration = self.count(doc, "n_exploration", "search.")
        n_exploitation = self.count(doc, "n_exploitation", "search.")
        if n_exploration + n_exploitation != len(told):
            raise CheckpointError(
                f"{self.source}: search counts {n_exploration} exploration + {n_exploitation} exploitation "
                f"attempts, but {len(told)} were told"
            )
        return SearchSnapshot(
            tuple(told),
            phase,
            best,
            -math.inf if best_reward is None else best_reward,
            self.number(doc, "sigma", "search."),
            n_exploration,
            n_exploitation,
        )

    def segment(self, doc: Any, k: int) -> SegmentDigest:
        where = f"segments[{k}]."
        if not isinstance(doc, dict):
            raise CheckpointError(f"{self.source}: {where[:-1]} must be an object, got {doc!r:.80}")
        digest = self.get(doc, "digest", str, where)
        if len(digest) != _DIGEST_HEX or any(ch not in "0123456789abcdef" for ch in digest):
            raise CheckpointError(
                f"{self.source}: {where}digest must be {_DIGEST_HEX} hex digits, got {digest!r}"
            )
        return SegmentDigest(self.get(doc, "label", str, where), self.count(doc, "n_samples", where), digest)


__all__ = [
    "FORMAT_VERSION",
    "RNG_NAMES",
    "Checkpoint",
    "CheckpointError",
    "SearchSnapshot",
    "SegmentDigest",
    "capture",
    "restore",
]
