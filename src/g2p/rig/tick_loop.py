"""The rig's tick loop: what every rig does each tick (simulator node, hardware driver, `PlantRig`).

Each tick the loop decides one activation and steps the plant with it. In order of precedence: a reset
asked for (the plant returns to rest; no tick), the next row of the sequence being played, the activation
the trajectory tracker (g2p.rig.closed_loop) decides from the previous tick's sample, a command queued one
tick each (on-demand pacing), else the latest command through the `ActivationGate` (clamped to
[baseline, 1], baseline once commands stop). A cancelled job, a fault and a stop drop to baseline from the
coming tick on. At most one job (sequence or trajectory) or one reset is in progress at a time.

Every activation then passes the rig's safety envelope (g2p.rig.envelope: soft joint limits, the motors'
thermal budget), from the previous tick's measurements, whoever sent it. A limit that trips (the plant's
`fault`, or a winding estimated past its cut-out) trips the loop: the job ends with the reason, the motors
stay at baseline and commands and jobs are refused until a reset puts the rig right.

Every sample's time is put on the stamp grid (whole nanoseconds, g2p.plant.on_stamp_grid): in-process
and over ROS, a learner gets the same floats. Every tick, reset sample and idle heartbeat goes to `emit`
in order; a job or reset is done only once `emit`'s receiver calls the tick's `then`, so a ROS rig
reports a sequence done once its last tick is published. The loop runs in its own thread (`start()`), or
is stepped by its caller (`start(threaded=False)` and `tick()`), as `PlantRig` does. ros2_control is the
model: the loop knows nothing of topics.
"""

from __future__ import annotations

import enum
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from g2p.plant import Plant, TickSample, on_stamp_grid
from g2p.rig.closed_loop import TrajectoryTracker
from g2p.rig.envelope import EnvelopeAction, EnvelopeConfig, SafetyEnvelope
from g2p.safety import BASELINE_ACTIVATION, ActivationGate, check_activation_sequence
from g2p.validation import require

FloatArray = NDArray[np.float64]

# An idle loop with on-demand pacing emits a heartbeat this often (wall s): a ROS rig repeats its /clock,
# so that a node started while it idles gets the time before the next sequence.
IDLE_HEARTBEAT_PERIOD_S = 1.0
# The error of a job (and the message of a reset) that the loop's stop ended.
STOPPED = "rig stopped"


class RigTripped(RuntimeError):
    """A limit of the rig tripped (the message says which): the rig holds baseline until a reset."""


class Pacing(enum.Enum):
    """Who sets the pace of the tick loop."""

    WALL_CLOCK = "wall_clock"
    """Simulation in real time: the loop sleeps until each tick's end on the monotonic clock."""
    PLANT = "plant"
    """Hardware: `plant.step` itself blocks until the tick's absolute deadline."""
    ON_DEMAND = "on_demand"
    """Fast simulation: ticks only when there is work (a job, or one tick per command)."""


@dataclass(frozen=True)
class TickLoopConfig:
    """How the tick loop decides and paces ticks.

    Attributes:
        watchdog_ticks: ticks without a valid activation_cmd after which the motors drop to baseline.
        baseline_activation: activation always applied at least (dimensionless, the paper's 15%).
        fast_max_real_time_factor: in fast simulation (on-demand pacing), the most simulated seconds per
            wall second (dimensionless; 0 = unlimited), so that subscribers such as the recorder keep up.
        envelope: the safety envelope's rules (g2p.rig.envelope).
    """

    watchdog_ticks: int = 3
    baseline_activation: float = BASELINE_ACTIVATION
    fast_max_real_time_factor: float = 60.0
    envelope: EnvelopeConfig = field(default_factory=EnvelopeConfig)

    def __post_init__(self) -> None:
        require(self.watchdog_ticks >= 1, "watchdog_ticks", f"must be >= 1, got {self.watchdog_ticks}")
        require(
            0.0 <= self.baseline_activation < 1.0,
            "baseline_activation",
            f"must be in [0, 1), got {self.baseline_activation}",
        )
        require(
            self.fast_max_real_time_factor >= 0,
            "fast_max_real_time_factor",
            f"must be >= 0, got {self.fast_max_real_time_factor}",
        )


@dataclass
class Job:
    """A sequence (`activations`, shape (N, 3), checked) or a trajectory (`tracker`) for the loop to play.

    `samples` grows by one per tick played; `done` is set once the job ended (played whole, cancelled,
    failed or stopped) and its last tick was emitted; `error` says why it ended early ("" otherwise).
    """

    activations: FloatArray | None = None
    tracker: TrajectoryTracker | None = None
    samples: list[TickSample] = field(default_factory=list)
    cancel: bool = False
    error: str = ""
    done: threading.Event = field(default_factory=threading.Event)

    @property
    def ticks_total(self) -> int:
        """Ticks the job plays when it is not ended early."""
        if self.tracker is not None:
            return len(self.tracker)
        return 0 if self.activations is None else len(self.activations)

    def next_activation(self) -> FloatArray:
        """The coming tick's activation, checked as a sequence's rows are (finite, in [0, 1]).

        Raises:
            ValueError: closed loop: a non-finite measurement, or the map gave no valid activation.
        """
        k = len(self.samples)
        if self.tracker is None:
            assert self.activations is not None
            row: FloatArray = self.activations[k]  # checked whole when the job was made
            return row
        activation = self.tracker.next_activation(self.samples[-1] if k else None)
        checked: FloatArray = check_activation_sequence(activation[np.newaxis])[0]
        return checked


@dataclass
class ResetRequest:
    """A reset for the loop: `done` is set once the plant is at rest and its sample emitted, or failed."""

    success: bool = False
    message: str = ""
    done: threading.Event = field(default_factory=threading.Event)


@dataclass(frozen=True)
class Tick:
    """What the loop emits, in order.

    Attributes:
        sample: the tick's (or the reset's) sample; None for an idle heartbeat.
        number: ticks stepped since start, this one included (a reset sample repeats the last number).
        idles_after: the loop may not tick again soon (on-demand pacing with nothing more to play, a
            reset, the last tick at stop): the rig's time stands still after this one.
        then: to call once the tick is delivered (or cannot be): it ends the job or reset it finished.
        envelope: what the safety envelope did to the tick's activation (None for a reset sample or a
            heartbeat).
        trip: why the rig is tripped after this tick ("" when it is not).
    """

    sample: TickSample | None
    number: int
    idles_after: bool
    then: Callable[[], None] | None = None
    envelope: EnvelopeAction | None = None
    trip: str = ""


class CommandOutcome(enum.Enum):
    """What became of a command given to `TickLoop.command`."""

    APPLIED = "applied"
    """The gate holds it (clamped); the next ticks apply it."""
    REJECTED = "rejected"
    """Not 3 finite numbers: nothing changed."""
    IGNORED = "ignored"
    """A sequence or trajectory plays: commands wait until it ends."""
    TRIPPED = "tripped"
    """The rig is tripped: commands wait for a reset."""


@dataclass
class LoopCounters:
    """Counts since start, beside the gate's."""

    ticks: int = 0
    ignored_commands: int = 0
    faults: int = 0
    envelope_ticks: int = 0
    """Ticks whose activation the safety envelope changed."""
    trips: int = 0


class TickLoop:
    """The tick loop of one rig over `plant`.

    Args:
        plant: the plant; only the loop touches it after `start`.
        pacing: who paces the loop (see Pacing).
        config: watchdog, baseline and fast-simulation pace.
        emit: receives every tick, reset sample and heartbeat in order (from the loop's thread). An
            exception from it is a fault like the plant's.
        on_fault: called (from the loop's thread) with each exception of the plant or of `emit`, after
            the loop dropped to baseline and failed the job.
    """

    def __init__(
        self,
        plant: Plant,
        pacing: Pacing,
        config: TickLoopConfig = TickLoopConfig(),
        emit: Callable[[Tick], None] | None = None,
        on_fault: Callable[[Exception], None] | None = None,
    ) -> None:
        self.plant = plant
        self.pacing = pacing
        self.config = config
        self.gate = ActivationGate(config.watchdog_ticks, config.baseline_activation)
        self.envelope = SafetyEnvelope(config.envelope, config.baseline_activation)
        self.counters = LoopCounters()
        self.trip = ""
        """Why the rig is tripped ("" when it is not): set by a limit, cleared by a successful reset."""
        self._last: TickSample | None = None  # the last sample: the envelope's measurements
        self._emit = emit if emit is not None else _deliver
        self._on_fault = on_fault
        self._cv = threading.Condition()
        self._job: Job | None = None
        self._reserved = False
        self._reset: ResetRequest | None = None
        self._lockstep: deque[FloatArray] = deque()  # on-demand pacing: one tick per accepted command
        self._running = False
        self._thread: threading.Thread | None = None
        self._wall_start = 0.0
        self._burst: tuple[float, float] | None = None  # (wall, plant time) when on-demand ticking resumed

    # Life cycle ------------------------------------------------------------------------------------

    def start(self, t_s: float = 0.0, threaded: bool = True) -> None:
        """Start ticking: in a thread of the loop's own, or (threaded=False) on each call of `tick`.

        Args:
            t_s: the plant's time now (s), from which wall-clock pacing counts.
            threaded: run the loop in its own thread.
        """
        self._wall_start = time.monotonic() - t_s
        with self._cv:
            self._running = True
        if threaded:
            self._thread = threading.Thread(target=self._run, name="rig_tick_loop", daemon=True)
            self._thread.start()

    def stop(self) -> bool:
        """Stop the loop, end any job or pending reset, and emit one last tick at baseline (idempotent).

        Returns:
            Whether the loop was running.

        Raises:
            Exception: the plant's, when the last tick fails (a faulted plant: its close() makes it safe).
        """
        with self._cv:
            was_running, self._running = self._running, False
            if self._job is not None:
                self._job.error = STOPPED
                self._finish(self._job)
            if self._reset is not None:  # asked for, never started: its caller must not wait on
                self._reset.message = STOPPED
                self._reset.done.set()
                self._reset = None
            self._cv.notify_all()
        if not was_running:
            return False
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            if self._thread.is_alive():  # the plant blocks: it must not be stepped from here
                return True
        baseline = self.gate.stop()  # the last tick is at baseline, whatever the envelope would add
        action = self.envelope.limit(baseline, None, None)  # baseline stays baseline: nothing to limit
        sample = _on_grid(self.plant.step(action.applied))
        self.counters.ticks += 1
        self._emit(Tick(sample, self.counters.ticks, True, envelope=action, trip=self.trip))
        return True

    # What clients ask for --------------------------------------------------------------------------

    def command(self, activation: FloatArray | list[float]) -> CommandOutcome:
        """Give the loop an activation command (3 values; clamped to [baseline, 1])."""
        with self._cv:
            if self._job is not None:
                self.counters.ignored_commands += 1
                return CommandOutcome.IGNORED
            if self.trip:  # a lockstep client still gets its tick, at baseline
                if self.pacing is Pacing.ON_DEMAND:
                    self._lockstep.append(self.gate.baseline_activation)
                    self._cv.notify_all()
                return CommandOutcome.TRIPPED
            applied = self.gate.command(activation)
            if applied is None:
                return CommandOutcome.REJECTED
            if self.pacing is Pacing.ON_DEMAND:
                self._lockstep.append(applied)
                self._cv.notify_all()
            return CommandOutcome.APPLIED

    def reserve(self) -> bool:
        """Reserve the loop for one job, unless a job or a reset is in progress."""
        with self._cv:
            if self._reserved or self._reset is not None:
                return False
            self._reserved = True
            return True

    def play(self, job: Job) -> None:
        """Hand a job to the loop (after `reserve`); `job.done` tells when it ended."""
        with self._cv:
            if not self._running and not job.done.is_set():
                job.error = "rig is not running"
                job.done.set()
            if self.trip and not job.done.is_set():
                job.error = f"rig tripped: {self.trip}; reset it first"
                job.done.set()
            if not job.done.is_set():
                self._job = job
                self._cv.notify_all()

    def release(self) -> None:
        """Free the reservation once the job ended."""
        with self._cv:
            self._reserved = False

    def cancel(self) -> None:
        """Cancel the job being played: the loop drops to baseline on its next tick."""
        with self._cv:
            if self._job is not None:
                self._job.cancel = True

    def request_reset(self) -> ResetRequest | str:
        """Ask for a reset; returns its request (`done` tells when it is over), or why it is refused."""
        with self._cv:
            if self._reserved or self._reset is not None:
                return "a run_activations sequence, run_trajectory or reset is in progress"
            if not self._running:
                return "rig is not running"
            self._reset = ResetRequest()
            self._cv.notify_all()
            return self._reset

    # The loop --------------------------------------------------------------------------------------

    def _run(self) -> None:
        while self.tick():
            pass

    def tick(self) -> bool:
        """Wait for work (on-demand pacing), then do one reset or one tick; False once stopped."""
        with self._cv:
            while self._running and self.pacing is Pacing.ON_DEMAND and not self._has_work():
                self._burst = None
                if not self._cv.wait(IDLE_HEARTBEAT_PERIOD_S):
                    try:
                        self._emit(Tick(None, self.counters.ticks, True))
                    except Exception as err:  # the delivery failed: a fault; the loop goes on
                        self._fault(err, None)
            if not self._running:
                return False
            reset, self._reset = self._reset, None
            job, activation = (None, self.gate.baseline_activation) if reset else self._next_activation()
            idles_after = self._idles_after(job)
        try:
            if reset is not None:
                self._do_reset(reset)
                return True
            sample, action = self._step(activation)
            self._pace(sample.t_s)
            self.counters.ticks += 1
            then = self._advance(job, sample) if job is not None else None
            trip = self._check_trip()
            self._emit(Tick(sample, self.counters.ticks, idles_after, then, action, self.trip))
            if trip:
                self._fault(RigTripped(trip), job)
        except Exception as err:  # the plant (or the delivery) failed: baseline, fail the job, report
            self._fault(err, job)
        return True

    def _step(self, activation: FloatArray) -> tuple[TickSample, EnvelopeAction]:
        """One tick of the plant with `activation` through the envelope."""
        last = None if self.trip else self._last  # a tripped rig holds plain baseline
        action = self.envelope.limit(
            activation,
            None if last is None else last.position_rad,
            None if last is None else last.velocity_rad_s,
        )
        sample = _on_grid(self.plant.step(action.applied))
        self.envelope.observe(sample)
        self._last = sample
        if action.acted:
            self.counters.envelope_ticks += 1
        return sample, action

    def _check_trip(self) -> str:
        """A new trip's reason after a tick (the plant's, or the envelope's estimate), else ""."""
        if self.trip:
            return ""
        trip = getattr(self.plant, "fault", "") or self.envelope.trip
        if trip:
            with self._cv:
                self.trip = trip
                self.counters.trips += 1
                self.gate.stop()
                if self.pacing is Pacing.ON_DEMAND:  # one more tick: the rig is seen at baseline
                    self._lockstep.append(self.gate.baseline_activation)
        return trip

    def _has_work(self) -> bool:
        return self._job is not None or self._reset is not None or bool(self._lockstep)

    def _next_activation(self) -> tuple[Job | None, FloatArray]:
        """The job being played, if any, and the coming tick's activation (lock held)."""
        job = self._job
        if job is not None and not job.cancel:
            try:
                return job, job.next_activation()
            except ValueError as err:  # closed loop: no valid activation; end it, baseline from this tick
                job.error = f"no valid activation for tick {len(job.samples)}: {err}"
                self._finish(job)
                return None, self.gate.stop()
        if job is not None:  # cancelled: end the job now, baseline from this tick on
            self._finish(job)
            return None, self.gate.stop()
        if self.trip:
            if self._lockstep:
                self._lockstep.popleft()
            return None, self.gate.stop()
        if self._lockstep:
            return None, self._lockstep.popleft()
        return None, self.gate.next_activation()

    def _idles_after(self, job: Job | None) -> bool:
        """Whether the loop idles after the coming tick (lock held)."""
        if self.pacing is not Pacing.ON_DEMAND:
            return False
        if job is not None:
            return len(job.samples) + 1 == job.ticks_total
        return not self._lockstep

    def _advance(self, job: Job, sample: TickSample) -> Callable[[], None] | None:
        """Add the tick to the job; after its last tick, what ends it once that tick is delivered."""
        job.samples.append(sample)
        if len(job.samples) < job.ticks_total:
            return None
        with self._cv:
            self._unset(job)
            self.gate.stop()  # the job is over: baseline until the next command
        return job.done.set

    def _unset(self, job: Job) -> None:
        """The loop plays `job` no more (lock held)."""
        if self._job is job:
            self._job = None

    def _finish(self, job: Job) -> None:
        self._unset(job)
        job.done.set()

    def _do_reset(self, req: ResetRequest) -> None:
        try:
            sample = _on_grid(self.plant.reset())
        except Exception as err:
            req.success, req.message = False, f"reset failed: {err}"
            req.done.set()
            raise
        self.gate.stop()
        self._last = sample
        self.envelope.observe(sample, at_rest=True)  # the time a tripped rig took to cool
        was, self.trip = self.trip, getattr(self.plant, "fault", "") or self.envelope.trip
        if self.trip:
            req.success, req.message = False, f"rig still tripped: {self.trip}"
        else:
            req.success, req.message = True, "at rest" if not was else f"at rest, put right after: {was}"
        self._emit(Tick(sample, self.counters.ticks, True, req.done.set))

    def _fault(self, err: Exception, job: Job | None) -> None:
        self.counters.faults += 1
        with self._cv:
            self.gate.stop()
            if job is not None:
                job.error = f"plant fault: {err}"
                self._finish(job)
        if self._on_fault is not None:
            self._on_fault(err)

    def _pace(self, t_s: float) -> None:
        if self.pacing is Pacing.WALL_CLOCK:
            delay = self._wall_start + t_s - time.monotonic()
        elif self.pacing is Pacing.ON_DEMAND and self.config.fast_max_real_time_factor > 0:
            if self._burst is None:
                self._burst = (time.monotonic(), t_s)
            wall0, t0 = self._burst
            delay = wall0 + (t_s - t0) / self.config.fast_max_real_time_factor - time.monotonic()
        else:
            return
        if delay > 0:
            time.sleep(delay)


def _on_grid(sample: TickSample) -> TickSample:
    """The sample with its time in whole nanoseconds, as a ROS stamp carries it."""
    return replace(sample, t_s=on_stamp_grid(sample.t_s))


def _deliver(tick: Tick) -> None:
    """The receiver of a loop without one: every tick counts as delivered at once."""
    if tick.then is not None:
        tick.then()
