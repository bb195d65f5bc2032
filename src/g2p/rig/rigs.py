"""The rig as the learner sees it: reset to rest, play a whole sequence (or trajectory), get its samples.

A sequence is a fixed list of activations (open loop); a trajectory's activations are decided by the rig
tick by tick from the inverse map and the measured joint state (closed loop, g2p.rig.closed_loop).

The learner drives a `Rig`: an in-process plant wrapped by `PlantRig`, or the ROS 2 rig contract
(g2p_ros.rig_client.RigClient) served by the simulator or the hardware driver.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any, Protocol, TypeVar

import numpy as np
from numpy.typing import NDArray

from g2p.plant import NOMINAL_TICK_HZ, Plant, Recording, TickSample
from g2p.rig.closed_loop import TrackedRecording, Trajectory, TrajectoryTracker
from g2p.rig.tick_loop import Job, LoopCounters, Pacing, TickLoop, TickLoopConfig
from g2p.safety import check_activation_sequence

ProgressCallback = Callable[[int, int], None]

# The rig contract's default namespace: its topics, services and actions live under it.
DEFAULT_NAMESPACE = "/leg"


class RigError(RuntimeError):
    """The rig could not play a sequence or reset."""


class RigCancelled(RigError):
    """A sequence was cancelled on request; the rig dropped to baseline."""


class RigUnreachable(RigError):
    """The rig stopped answering (a cut link, a dead rig process): what it played since is unknown.

    The rig itself falls back to baseline once it has nothing valid to play; a sequence it was playing
    plays to its end (it is a valid sequence), then baseline.
    """


class Rig(Protocol):
    """Sequence-level access to a leg on a treadmill."""

    def reset(self) -> None:
        """Return to the resting posture every attempt starts from."""
        ...

    def play(
        self,
        activations: NDArray[np.float64],
        progress: ProgressCallback | None = None,
        cancel: threading.Event | None = None,
    ) -> Recording:
        """Play activations (N, 3) one row per tick and return the N recorded ticks.

        Raises:
            RigError: the sequence could not be played whole.
            RigCancelled: `cancel` was set before the end.
        """
        ...

    def play_trajectory(
        self,
        trajectory: Trajectory,
        progress: ProgressCallback | None = None,
        cancel: threading.Event | None = None,
    ) -> TrackedRecording:
        """Play a trajectory in closed loop, the map evaluated by the rig each tick (g2p.rig.closed_loop).

        Raises:
            RigError: the trajectory could not be played whole.
            RigCancelled: `cancel` was set before the end.
        """
        ...


class PlantRig:
    """A `Rig` over an in-process plant (no ROS): for fast experiments and tests.

    The plant is driven by the rig's own tick loop (g2p.rig.tick_loop), stepped from the caller's thread and
    unpaced: the same ticks as the simulator node plays for the same calls.

    Args:
        plant: the plant to drive.
        progress_every: ticks between progress callbacks.
        config: the tick loop's settings (default TickLoopConfig(); unpaced: the loop ticks as fast as
            it can).
    """

    def __init__(
        self,
        plant: Plant,
        progress_every: int = round(NOMINAL_TICK_HZ),
        config: TickLoopConfig | None = None,
    ) -> None:
        self.plant = plant
        self._progress_every = progress_every
        unpaced = replace(config or TickLoopConfig(), fast_max_real_time_factor=0.0)
        self._loop = TickLoop(plant, Pacing.ON_DEMAND, unpaced)
        self._loop.start(threaded=False)

    @property
    def counters(self) -> LoopCounters:
        """The rig's tick loop's counters: ticks, faults, ticks the safety envelope changed, trips."""
        return self._loop.counters

    def reset(self) -> None:
        """Reset the plant to rest.

        Raises:
            RigError: the plant failed to reset.
        """
        req = self._loop.request_reset()
        assert not isinstance(req, str), req  # one caller, one call at a time: never refused
        while not req.done.is_set():
            self._loop.tick()
        if not req.success:
            raise RigError(req.message)

    def play(
        self,
        activations: NDArray[np.float64],
        progress: ProgressCallback | None = None,
        cancel: threading.Event | None = None,
    ) -> Recording:
        """Play the sequence on the plant, tick by tick."""
        job = Job(activations=check_activation_sequence(activations))
        return Recording.from_samples(self._play("sequence", job, progress, cancel))

    def play_trajectory(
        self,
        trajectory: Trajectory,
        progress: ProgressCallback | None = None,
        cancel: threading.Event | None = None,
    ) -> TrackedRecording:
        """Play the trajectory on the plant in closed loop, tick by tick."""
        job = Job(tracker=TrajectoryTracker(trajectory, 1.0 / self.plant.tick_hz))
        samples = self._play("trajectory", job, progress, cancel)
        assert job.tracker is not None
        return TrackedRecording(Recording.from_samples(samples), job.tracker.correction_rad_s)

    def _play(
        self,
        what: str,
        job: Job,
        progress: ProgressCallback | None,
        cancel: threading.Event | None,
    ) -> list[TickSample]:
        """Tick the loop until `job` ended; a cancel plays one tick at baseline, as the ROS rig does.

        Raises:
            RigCancelled: `cancel` was set before the end.
            RigError: the job failed (a plant fault, no valid activation in closed loop).
        """
        n = job.ticks_total
        reserved = self._loop.reserve()
        assert reserved, "one caller, one call at a time: never refused"
        self._loop.play(job)
        try:
            while not job.done.is_set():
                if cancel is not None and cancel.is_set():
                    self._loop.cancel()
                self._loop.tick()
                k = len(job.samples)
                if progress is not None and not job.cancel and k % self._progress_every == 0 and k < n:
                    progress(k, n)
        finally:
            self._loop.release()
        if job.cancel:
            raise RigCancelled(f"{what} cancelled after {len(job.samples)} of {n} ticks")
        if job.error:
            raise RigError(f"{what} failed after {len(job.samples)} of {n} ticks: {job.error}")
        if progress is not None:
            progress(n, n)
        return job.samples


class RigBusy(RigError):
    """The rig refused a sequence or reset because it still plays another one.

    For example a goal that arrived late over a lossy link, after the learner had given it up: it plays
    to its end by itself, then baseline.
    """


RigEventCallback = Callable[[str, dict[str, Any]], None]
_Played = TypeVar("_Played", Recording, TrackedRecording)


class RetryingRig:
    """A `Rig` whose calls survive the rig going away for up to `limit_s`: lost work is redone from rest.

    A `play` or `reset` that fails with RigUnreachable or RigBusy is not used: once the rig answers a reset,
    the sequence is played again, whole, from rest (an attempt starts from rest anyway; a babbling chunk
    that followed another starts from rest instead). So a caller only ever gets complete recordings, and a
    sequence whose data is incomplete is never used. When the rig does not answer within `limit_s` of
    losing it, RigUnreachable is raised and the caller ends its run.

    Args:
        rig: the rig to drive (e.g. the ROS rig client).
        limit_s: longest time without the rig before giving up (s).
        retry_pause_s: pause between two failed resets (s).
        on_event: told ("rig_lost", {"error": ..., "call": ...}) when a call failed, and
            ("rig_back", {"downtime_s": ..., "retries": ...}) once the rig answers again.
    """

    def __init__(
        self,
        rig: Rig,
        limit_s: float,
        retry_pause_s: float = 0.5,
        on_event: RigEventCallback | None = None,
    ) -> None:
        self._rig = rig
        self._limit_s = limit_s
        self._retry_pause_s = retry_pause_s
        self._on_event = on_event
        self.retries = 0
        """Calls redone because the rig was lost, since construction."""

    def reset(self) -> None:
        """Reset the rig, waiting for it to come back if it is lost."""
        try:
            self._rig.reset()
        except (RigUnreachable, RigBusy) as err:
            self._recover("reset", err, None)

    def play(
        self,
        activations: NDArray[np.float64],
        progress: ProgressCallback | None = None,
        cancel: threading.Event | None = None,
    ) -> Recording:
        """Play the sequence; if the rig is lost meanwhile, play it again from rest once it is back."""
        return self._retry("play", lambda: self._rig.play(activations, progress, cancel), cancel)

    def play_trajectory(
        self,
        trajectory: Trajectory,
        progress: ProgressCallback | None = None,
        cancel: threading.Event | None = None,
    ) -> TrackedRecording:
        """Play the trajectory; if the rig is lost meanwhile, play it again from rest once it is back."""
        return self._retry(
            "play_trajectory", lambda: self._rig.play_trajectory(trajectory, progress, cancel), cancel
        )

    def _retry(self, call: str, play: Callable[[], _Played], cancel: threading.Event | None) -> _Played:
        first_lost: float | None = None  # the limit counts from the first loss: a sequence that never
        while True:  # gets through ends the run, even if resets do
            try:
                return play()
            except (RigUnreachable, RigBusy) as err:
                first_lost = time.monotonic() if first_lost is None else first_lost
                self._recover(call, err, cancel, first_lost)
                self.retries += 1

    def _recover(
        self, call: str, err: RigError, cancel: threading.Event | None, lost_at: float | None = None
    ) -> None:
        """Reset until the rig answers.

        Raises:
            RigUnreachable: `limit_s` passed since `lost_at` (default: now).
            RigCancelled: `cancel` was set.
        """
        lost_at = time.monotonic() if lost_at is None else lost_at
        self._tell("rig_lost", {"call": call, "error": str(err)})
        resets = 0
        last_error: RigError = err
        while True:
            if cancel is not None and cancel.is_set():
                raise RigCancelled("cancel requested while waiting for the rig")
            waited = time.monotonic() - lost_at
            if waited >= self._limit_s:
                raise RigUnreachable(
                    f"the rig has not played the sequence for {waited:.0f} s (limit {self._limit_s:g} s); "
                    f"last error: {last_error}"
                ) from last_error
            resets += 1
            try:
                self._rig.reset()
            except RigCancelled:
                raise
            except RigError as retry_err:
                last_error = retry_err
                time.sleep(self._retry_pause_s)
                continue
            downtime = round(time.monotonic() - lost_at, 3)
            self._tell("rig_back", {"downtime_s": downtime, "resets": resets})
            return

    def _tell(self, event: str, detail: dict[str, Any]) -> None:
        if self._on_event is not None:
            self._on_event(event, detail)
