"""Where a recorded treadmill run can continue: its last checkpoint and the data the learner had then.

The learner publishes a "checkpoint" event after the babbling fit and after every attempt of a `learn`
run (g2p.learning.checkpoint: map, validation split, generators, search). With the run's babbling segments
and completed attempts read back from the same bag, `g2p.learning.checkpoint.restore` rebuilds the learner
exactly. The bag may still be being recorded (the recorder beside the rig keeps recording while the learner is
restarted): it is then read from a recovered copy, and the original is left untouched.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from g2p.bags.dataset import RunData, load_run
from g2p.bags.errors import BagError
from g2p.bags.recover import bag_is_complete, recover_bag
from g2p.learning.checkpoint import Checkpoint, CheckpointError, restore
from g2p.learning.experiments import TreadmillRun
from g2p.learning.learner import LearnerConfig
from g2p.learning.limit_cycle import LimitCycleConfig
from g2p.learning.run_events import CHECKPOINT, SEARCH, Event
from g2p.learning.search import SearchConfig
from g2p.plant import Recording
from g2p.rig import DEFAULT_NAMESPACE

TREADMILL_PHASES = ("exploration", "exploitation")


class ResumeError(ValueError):
    """A bag holds no run that can be continued; the message names the bag and what is missing."""


@dataclass(frozen=True)
class ResumePoint:
    """A run's state at its last checkpoint, and the data the learner had then.

    Attributes:
        bag: the bag directory.
        run_id: the run's id (the continuation keeps it).
        checkpoint: the last checkpoint of the run.
        babbling: the run's babbling recordings, one per chunk, in order.
        attempts: the recordings of the attempts the checkpoint covers (1..checkpoint.attempt), in order.
        search: the run's search settings, as its run_start event recorded them.
        node_config: the learner node's configuration, as recorded on its `~/config` topic (None if absent).
    """

    bag: Path
    run_id: str
    checkpoint: Checkpoint
    babbling: list[Recording]
    attempts: list[Recording]
    search: dict[str, Any]
    node_config: dict[str, Any] | None


def resume_point(
    bag: Path | str, config_topic: str = "/leg/learner/config", rig_namespace: str = DEFAULT_NAMESPACE
) -> ResumePoint:
    """Read a recorded run's last checkpoint and its data.

    Args:
        bag: the bag directory (complete, or still being recorded, or left by a killed recorder).
        config_topic: the learner node's configuration topic.
        rig_namespace: namespace of the rig topics.

    Raises:
        ResumeError: no learn run, no checkpoint, or the data the checkpoint needs is not in the bag.
        BagReadError: the bag cannot be read.
    """
    path = Path(bag)
    if not path.is_dir():
        raise ResumeError(f"{path}: not a bag directory")
    run = _read(path, rig_namespace)
    starts = [e for e in run.events if e.event == Event.RUN_START and SEARCH in e.detail]
    if not starts:
        raise ResumeError(f"{path}: no learn run in this bag (no run_start event with search settings)")
    start = starts[0]
    events = [e for e in run.events if e.run_id == start.run_id and e.stamp_ns >= start.stamp_ns]
    checkpoints = [e for e in events if e.event == Event.CHECKPOINT]
    if not checkpoints:
        raise ResumeError(f"{path}: run {start.run_id} has no checkpoint (it ended before its first fit)")
    try:
        checkpoint = Checkpoint.from_json(json.dumps(checkpoints[-1].detail.get(CHECKPOINT)), str(path))
    except CheckpointError as err:
        raise ResumeError(str(err)) from err
    babbling = [
        segment
        for segment, opening in zip(run.babbling_segments, _babbling_starts(run), strict=True)
        if opening >= start.stamp_ns
    ]
    # Every attempt number once: the last completed recording of it (an attempt cut by a crash and
    # played again after a resume has an earlier, unfinished one).
    completed: dict[int, Recording] = {}
    for attempt in run.attempts:
        if (
            attempt.end is not None
            and attempt.phase in TREADMILL_PHASES
            and attempt.start.run_id == start.run_id
        ):
            completed[attempt.attempt] = attempt.recording
    missing = [k for k in range(1, checkpoint.attempt + 1) if k not in completed]
    if missing:
        raise ResumeError(
            f"{path}: the checkpoint after attempt {checkpoint.attempt} needs attempts {missing}"
        )
    config = run.configs.get(config_topic)
    return ResumePoint(
        bag=path,
        run_id=start.run_id,
        checkpoint=checkpoint,
        babbling=babbling,
        attempts=[completed[k] for k in range(1, checkpoint.attempt + 1)],
        search=dict(start.detail[SEARCH]),
        node_config=config if isinstance(config, dict) else None,
    )


def resume_run(
    bag: Path | str,
    node_config: dict[str, Any],
    learner: LearnerConfig,
    cycle: LimitCycleConfig,
    config_topic: str = "/leg/learner/config",
) -> tuple[ResumePoint, TreadmillRun]:
    """The run recorded in `bag`, restored at its last checkpoint, to be continued with these settings.

    Args:
        bag: the run's bag directory.
        node_config: the continuing learner's configuration as it records it (its `~/config`, JSON
            types): its "learner" and "cycle" sections must be the recorded run's.
        learner: the learner's settings.
        cycle: the limit-cycle settings.
        config_topic: the recorded learner's configuration topic.

    Raises:
        ResumeError: the bag holds no run to continue.
        ValueError: the learner and cycle settings are not the recorded run's (the search's come from
            the bag), or the checkpoint does not match the recorded data.
    """
    point = resume_point(bag, config_topic)
    if point.node_config is not None:
        differ = [k for k in ("learner", "cycle") if point.node_config.get(k) != node_config.get(k)]
        if differ:
            raise ValueError(
                f"{bag}: the recorded run's {' and '.join(differ)} settings differ from this node's; "
                "start the learner with the run's parameters (see its ~/config in the bag)"
            )
    try:
        run = restore(
            point.checkpoint, point.babbling, point.attempts, learner, SearchConfig(**point.search), cycle
        )
    except CheckpointError as err:
        raise ValueError(f"{bag}: {err}") from err
    return point, run


def _babbling_starts(run: RunData) -> list[int]:
    """The stamp of each babbling segment's opening event, in the order of `run.babbling_segments`."""
    return [e.stamp_ns for e in run.events if e.phase == "babbling" and e.event == Event.PHASE_START]


def _read(path: Path, rig_namespace: str) -> RunData:
    """The run in the bag; one without its summary (being recorded, a killed recorder's) from a copy."""
    if bag_is_complete(path):
        return load_run(path, rig_namespace)
    with tempfile.TemporaryDirectory(prefix="g2p-resume-") as tmp:
        copy = Path(tmp) / path.name
        shutil.copytree(path, copy)
        try:
            recover_bag(copy)
        except BagError as err:
            raise ResumeError(f"{path}: cannot read the bag being recorded: {err}") from err
        return load_run(copy, rig_namespace)
