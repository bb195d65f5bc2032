"""The rig contract served over ROS 2 for any plant: the simulator and the hardware driver share it.

One tick loop, in its own thread, decides each tick's activation (the next row of a running
`run_activations` sequence, or of a running `run_trajectory`, decided by the core's
`g2p.closed_loop.TrajectoryTracker` from the previous tick's sample; else the latest `activation_cmd`
through the watchdog, else baseline) and steps the plant; a publisher thread publishes each tick's four
messages with one shared stamp, in order, while the loop steps the next tick (MuJoCo steps without the GIL,
so stepping and publishing overlap). A sequence, trajectory or reset is reported done only once its last
tick is published. Executor callbacks only validate goals and hand work to the loop; at most one goal of
either action, or one reset, runs at a time.
"""

from __future__ import annotations

import enum
import queue
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.action.server import ServerGoalHandle
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.publisher import Publisher
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Header
from std_srvs.srv import Trigger

from g2p.closed_loop import TrajectoryTracker
from g2p.config import require
from g2p.plant import N_JOINTS, NOMINAL_TICK_HZ, Plant, Recording, TickSample
from g2p.safety import BASELINE_ACTIVATION, ActivationGate, InvalidActivation, check_activation_sequence
from g2p_interfaces.action import RunActivations, RunTrajectory
from g2p_interfaces.msg import MotorActivation, MotorPower, Treadmill
from g2p_ros import contract
from g2p_ros.convert import TickSerializer, rig_samples_msg, stamp_ns, time_from_ns, trajectory_from_goal


class Pacing(enum.Enum):
    """Who sets the pace of the tick loop."""

    WALL_CLOCK = "wall_clock"
    """Simulation in real time: the loop sleeps until each tick's end on the monotonic clock."""
    PLANT = "plant"
    """Hardware: `plant.step` itself blocks until the tick's absolute deadline."""
    ON_DEMAND = "on_demand"
    """Fast simulation: ticks only when there is work (a goal, or one tick per command), unpaced."""


@dataclass(frozen=True)
class RigServerConfig:
    """How the rig contract is served.

    Attributes:
        watchdog_ticks: ticks without a valid activation_cmd after which the motors drop to baseline.
        baseline_activation: activation always applied at least (dimensionless, the paper's 15%).
        feedback_period_s: wall time between run_activations and run_trajectory feedback messages (s).
        diagnostics_period_ticks: ticks between /diagnostics messages (78 = about 1 s of rig time).
        log_period_s: minimum wall time between two warnings about rejected or ignored commands (s).
        fast_max_real_time_factor: in fast simulation (on-demand pacing), the most simulated seconds per
            wall second (dimensionless; 0 = unlimited), so that subscribers such as the recorder keep up.
        clock_period_ticks: ticks between /clock messages (when the rig publishes /clock); the last tick
            before the rig idles and every reset are always published, so the clock is never behind a
            finished sequence. Every /clock message costs each use_sim_time node an executor callback.
        command_max_age_s: an activation_cmd stamped longer ago than this, on the rig's clock, is ignored
            (s; 0 = no check; an unstamped command is not checked): a command held up by a network fault
            must not move the motors when it finally arrives. Across hosts, their clocks must agree to well
            within this (chrony; docs/DEPLOYMENT.md).
        flush_timeout_s: on stopping, how long to wait for every subscriber (the recorder) to acknowledge
            the ticks already published before the publishers are destroyed (s). A reliable sample lost
            on the way is resent only while its publisher exists.
    """

    watchdog_ticks: int = 3
    baseline_activation: float = BASELINE_ACTIVATION
    feedback_period_s: float = 0.2
    diagnostics_period_ticks: int = round(NOMINAL_TICK_HZ)
    log_period_s: float = 1.0
    fast_max_real_time_factor: float = 60.0
    clock_period_ticks: int = 1
    command_max_age_s: float = 0.5
    flush_timeout_s: float = 5.0

    def __post_init__(self) -> None:
        require(
            self.clock_period_ticks >= 1, "clock_period_ticks", f"must be >= 1, got {self.clock_period_ticks}"
        )
        require(self.flush_timeout_s >= 0, "flush_timeout_s", f"must be >= 0, got {self.flush_timeout_s}")
        require(
            self.command_max_age_s >= 0, "command_max_age_s", f"must be >= 0, got {self.command_max_age_s}"
        )


@dataclass
class _Job:
    """A goal being played by the loop.

    Either a run_activations sequence (`activations`) or a run_trajectory (`tracker`, which decides each
    tick's activation from the previous tick's sample).
    """

    activations: np.ndarray | None = None
    tracker: TrajectoryTracker | None = None
    samples: list[TickSample] = field(default_factory=list)
    cancel: bool = False
    error: str = ""
    done: threading.Event = field(default_factory=threading.Event)

    @property
    def ticks_total(self) -> int:
        if self.tracker is not None:
            return len(self.tracker)
        return 0 if self.activations is None else len(self.activations)

    def next_activation(self) -> np.ndarray:
        """The coming tick's activation, checked as a sequence's rows are (finite, in [0, 1]).

        Raises:
            ValueError: closed loop: a non-finite measurement, or the map gave no valid activation.
        """
        k = len(self.samples)
        if self.tracker is None:
            assert self.activations is not None
            return self.activations[k]  # checked whole when the goal arrived
        activation = self.tracker.next_activation(self.samples[-1] if k else None)
        return check_activation_sequence(activation[np.newaxis])[0]


@dataclass(frozen=True)
class _Outgoing:
    """A tick for the publisher thread; `then` is called once it is published (or cannot be).

    Without a sample, only the last tick's time goes out again on /clock.
    """

    sample: TickSample | None
    clock: bool
    then: Callable[[], None] | None = None


# An idle fast simulation repeats its /clock this often (wall s): a node started while it idles (a
# learner resuming a run) gets the time, rather than 0, before the next sequence.
IDLE_CLOCK_PERIOD_S = 1.0
# Ticks the loop may run ahead of the publisher before it waits (3 s of rig time at 78 Hz).
_OUTBOX_TICKS = 256


@dataclass
class _ResetRequest:
    message: str = ""
    success: bool = False
    done: threading.Event = field(default_factory=threading.Event)


class RigServer:
    """Serves the rig contract for `plant` on `node`, with topics relative to the node's namespace.

    Args:
        node: the node to create publishers, subscriptions, the action and the service on.
        plant: the plant; only the loop thread touches it after `start`.
        pacing: who paces the loop (see Pacing).
        config: watchdog and reporting settings.
        sim_time: stamp ticks with the plant's own clock from 0 (simulation time); otherwise with system
            time. Either way the stamps are published on /clock when `publish_clock` is set.
        publish_clock: publish every tick's stamp on /clock (simulators).
        on_fault: called from the loop thread when the plant raises; the loop drops to baseline.
    """

    def __init__(
        self,
        node: Node,
        plant: Plant,
        pacing: Pacing,
        config: RigServerConfig = RigServerConfig(),
        sim_time: bool = False,
        publish_clock: bool = False,
        on_fault: Callable[[Exception], None] | None = None,
    ) -> None:
        self._node = node
        self._plant = plant
        self._pacing = pacing
        self._config = config
        self._sim_time = sim_time
        self._on_fault = on_fault
        self._log = node.get_logger()
        self._gate = ActivationGate(config.watchdog_ticks, config.baseline_activation)
        self._cv = threading.Condition()
        self._job: _Job | None = None
        self._goal_reserved = False
        self._reset: _ResetRequest | None = None
        self._lockstep: deque[np.ndarray] = deque()  # fast simulation: one tick per accepted command
        self._ignored_commands = 0
        self._ticks = 0  # stepped (loop thread)
        self._published = 0  # published (publisher thread)
        self._faults = 0
        self._running = False
        self._thread: threading.Thread | None = None
        self._outbox: queue.Queue[_Outgoing | None] = queue.Queue(maxsize=_OUTBOX_TICKS)
        self._publisher: threading.Thread | None = None
        self._publish_error: Exception | None = None  # raised in the publisher, handled by the loop
        self._stamp_offset_s = 0.0
        self._wall_start = 0.0
        self._burst: tuple[float, float] | None = None  # (wall, plant time) when on-demand ticking resumed
        self._last_log = {"rejected": 0.0, "ignored": 0.0, "stale": 0.0}
        self._stale_commands = 0
        self._last_clock_ns: int | None = None  # the rig's clock: the last tick's stamp (publisher thread)

        qos = contract.SAMPLE_QOS
        self._pub_joints = node.create_publisher(JointState, contract.JOINT_STATES, qos)
        self._pub_treadmill = node.create_publisher(Treadmill, contract.TREADMILL, qos)
        self._pub_power = node.create_publisher(MotorPower, contract.MOTOR_POWER, qos)
        self._pub_applied = node.create_publisher(MotorActivation, contract.APPLIED_ACTIVATION, qos)
        self._serializer = TickSerializer()  # publishes serialized messages: cheaper, see its docstring
        self._pub_clock = (
            node.create_publisher(Clock, "/clock", contract.CLOCK_QOS) if publish_clock else None
        )
        self._pub_diag = node.create_publisher(DiagnosticArray, "/diagnostics", contract.DIAGNOSTICS_QOS)
        group = ReentrantCallbackGroup()
        # Commands in arrival order: their own mutually exclusive group.
        self._sub_cmd = node.create_subscription(
            MotorActivation,
            contract.ACTIVATION_CMD,
            self._on_command,
            contract.COMMAND_QOS,
            callback_group=MutuallyExclusiveCallbackGroup(),
        )
        self._action = ActionServer(
            node,
            RunActivations,
            contract.action_name(node, contract.RUN_ACTIVATIONS),
            execute_callback=self._execute,
            goal_callback=self._on_goal,
            cancel_callback=self._on_cancel,
            callback_group=group,
        )
        self._trajectory_action = ActionServer(
            node,
            RunTrajectory,
            contract.action_name(node, contract.RUN_TRAJECTORY),
            execute_callback=self._execute_trajectory,
            goal_callback=self._on_trajectory_goal,
            cancel_callback=self._on_cancel,
            callback_group=group,
        )
        self._srv_reset = node.create_service(Trigger, contract.RESET, self._on_reset, callback_group=group)

    # Life cycle ------------------------------------------------------------------------------------

    def start(self) -> None:
        """Reset the plant to rest and start the tick loop thread.

        The rest sample is not published, only its stamp on /clock: published before any subscriber
        could match, it would reach each subscriber on some topics and not others.
        """
        first = self._plant.reset()
        self._stamp_offset_s = 0.0 if self._sim_time else time.time() - first.t_s
        self._wall_start = time.monotonic() - first.t_s
        self._last_clock_ns = stamp_ns(self._stamp(first.t_s))
        self._publish_clock()
        self._running = True
        self._publisher = threading.Thread(target=self._publish_loop, name="rig_publisher", daemon=True)
        self._publisher.start()
        self._thread = threading.Thread(target=self._loop, name="rig_tick_loop", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the loop, abort any sequence or trajectory and leave the plant at baseline (idempotent).

        The last tick published is one at baseline, played after the loop ended: every subscriber (and so
        the bag) sees the rig stop safe. Then every subscriber's acknowledgement of every tick is awaited.
        """
        with self._cv:
            was_running, self._running = self._running, False
            if self._job is not None:
                self._job.error = "rig stopped"
                self._finish(self._job)
            if self._reset is not None:  # asked for, never started: its caller must not wait on
                self._reset.message = "rig stopped"
                self._reset.done.set()
                self._reset = None
            self._cv.notify_all()
        if not was_running:
            return
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        baseline = self._gate.stop()
        if self._thread is not None and not self._thread.is_alive():
            try:
                self._outbox.put(_Outgoing(self._plant.step(baseline), True))
                self._ticks += 1
            except Exception as err:  # a faulted plant: its close() makes it safe
                self._log.error(f"no final baseline tick: {type(err).__name__}: {err}")
        if self._publisher is not None:
            self._outbox.put(None)  # after the ticks already queued
            self._publisher.join(timeout=5.0)
        self._flush()
        last = "none" if self._last_clock_ns is None else f"{self._last_clock_ns} ns"
        self._log.info(
            f"stopped after publishing {self._published} ticks, the last at baseline (stamp {last})"
        )

    def _flush(self) -> None:
        """Wait until every subscriber acknowledged every published tick, up to `flush_timeout_s`."""
        if not self._node.context.ok():
            self._log.warning("the ROS context is shut down: ticks not yet acknowledged may be lost")
            return
        start = time.monotonic()
        deadline = start + self._config.flush_timeout_s
        unacked = [
            p.topic_name
            for p in self._sample_publishers
            if not p.wait_for_all_acked(Duration(seconds=max(0.0, deadline - time.monotonic())))
        ]
        if unacked:
            self._log.warning(
                f"stopping with ticks not acknowledged after {self._config.flush_timeout_s:g} s on "
                f"{', '.join(unacked)}: a subscriber (the recorder?) may miss them"
            )
        elif time.monotonic() - start > 0.01:
            self._log.info(
                f"waited {time.monotonic() - start:.2f} s for subscribers to acknowledge the last ticks"
            )

    @property
    def _sample_publishers(self) -> tuple[Publisher, ...]:
        return (self._pub_joints, self._pub_treadmill, self._pub_power, self._pub_applied)

    def destroy(self) -> None:
        """Stop and destroy the ROS entities this server created."""
        self.stop()
        self._action.destroy()
        self._trajectory_action.destroy()
        for entity in (
            *self._sample_publishers,
            self._pub_clock,
            self._pub_diag,
        ):
            if entity is not None:
                self._node.destroy_publisher(entity)
        self._node.destroy_subscription(self._sub_cmd)
        self._node.destroy_service(self._srv_reset)

    # Executor callbacks: validate, hand over to the loop, wait ----------------------------------------

    def _on_command(self, msg: MotorActivation) -> None:
        age_s = self._command_age_s(msg.header.stamp)
        if age_s is not None and 0 < self._config.command_max_age_s < age_s:
            self._stale_commands += 1
            self._warn(
                "stale",
                f"activation_cmd ignored: stamped {age_s:.2f} s ago, older than rig.command_max_age_s "
                f"({self._config.command_max_age_s:g} s): late after a network fault, or the hosts' clocks "
                f"disagree ({self._stale_commands} so far)",
            )
            return
        with self._cv:
            if self._job is not None:
                self._ignored_commands += 1
                self._warn(
                    "ignored",
                    "activation_cmd ignored while a run_activations or run_trajectory goal plays "
                    f"({self._ignored_commands} so far)",
                )
                return
            applied = self._gate.command(msg.activation)
            if applied is None:
                self._warn(
                    "rejected",
                    f"activation_cmd rejected (needs 3 finite values): {list(msg.activation)} "
                    f"({self._gate.counters.rejected} rejected so far)",
                )
                return
            if self._pacing is Pacing.ON_DEMAND:
                self._lockstep.append(applied)
                self._cv.notify_all()

    def _command_age_s(self, stamp: Time) -> float | None:
        """How long ago a command was stamped on the rig's clock (s); None when unstamped or unknown."""
        stamp_ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        now_ns = self._last_clock_ns if self._sim_time else time.time_ns()
        if stamp_ns == 0 or now_ns is None:
            return None
        return (now_ns - stamp_ns) * 1e-9

    def _on_goal(self, goal: RunActivations.Goal) -> GoalResponse:
        n = len(goal.activation)
        try:
            if n % 3:
                raise InvalidActivation(f"activation has {n} values, not a multiple of 3")
            check_activation_sequence(np.asarray(goal.activation).reshape(-1, 3))
        except InvalidActivation as err:
            self._log.warning(f"run_activations goal rejected: {err}")
            return GoalResponse.REJECT
        return self._reserve(contract.RUN_ACTIVATIONS)

    def _on_trajectory_goal(self, goal: RunTrajectory.Goal) -> GoalResponse:
        # ROS actions carry no reason for a rejection: this log line is it (RigClient checks the same
        # before sending, and raises with the reason).
        try:
            trajectory_from_goal(goal)
        except ValueError as err:  # ConfigError, InverseMapFormatError, a wrong shape or lead
            self._log.warning(f"run_trajectory goal rejected: {err}")
            return GoalResponse.REJECT
        return self._reserve(contract.RUN_TRAJECTORY)

    def _reserve(self, action: str) -> GoalResponse:
        """Accept a valid goal unless a goal of either action or a reset is in progress."""
        with self._cv:
            if self._goal_reserved or self._reset is not None:
                self._log.warning(f"{action} goal rejected: another sequence or a reset is in progress")
                return GoalResponse.REJECT
            self._goal_reserved = True
        return GoalResponse.ACCEPT

    def _on_cancel(self, goal_handle: ServerGoalHandle) -> CancelResponse:
        with self._cv:
            if self._job is not None:
                self._job.cancel = True  # the loop drops to baseline on its next tick
        return CancelResponse.ACCEPT

    def _execute(self, goal_handle: ServerGoalHandle) -> RunActivations.Result:
        job = _Job(activations=np.asarray(goal_handle.request.activation, dtype=np.float64).reshape(-1, 3))
        samples = self._play(goal_handle, job, RunActivations.Feedback())
        return RunActivations.Result(samples=self._samples_msg(samples), message=self._end(goal_handle, job))

    def _execute_trajectory(self, goal_handle: ServerGoalHandle) -> RunTrajectory.Result:
        job = _Job()
        try:
            job.tracker = TrajectoryTracker(
                trajectory_from_goal(goal_handle.request), 1.0 / self._plant.tick_hz
            )
        except ValueError as err:  # validated when it arrived: cannot happen
            job.error = f"invalid goal: {err}"
            job.done.set()
        samples = self._play(goal_handle, job, RunTrajectory.Feedback())
        correction = (
            job.tracker.correction_rad_s[: len(samples)]
            if job.tracker is not None
            else np.zeros((0, N_JOINTS))
        )
        return RunTrajectory.Result(
            samples=self._samples_msg(samples),
            correction_rad_s=correction.ravel(),
            message=self._end(goal_handle, job),
        )

    def _play(self, goal_handle: ServerGoalHandle, job: _Job, feedback: Any) -> list[TickSample]:
        """Hand `job` to the loop, send feedback every period until it ends; returns the ticks played."""
        with self._cv:
            if not self._running and not job.done.is_set():
                job.error = "rig is not running"
                job.done.set()
            if not job.done.is_set():
                self._job = job
                self._cv.notify_all()
        feedback.ticks_total = job.ticks_total
        while True:  # feedback every period while the loop plays, and once at the end
            finished = job.done.wait(self._config.feedback_period_s)
            feedback.ticks_done = len(job.samples)
            goal_handle.publish_feedback(feedback)
            if finished:
                break
        with self._cv:
            self._goal_reserved = False
        return list(job.samples)

    def _samples_msg(self, samples: list[TickSample]) -> Any:
        stamps = np.array([stamp_ns(self._stamp(sample.t_s)) for sample in samples], dtype=np.int64)
        return rig_samples_msg(Recording.from_samples(samples), stamps)

    @staticmethod
    def _end(goal_handle: ServerGoalHandle, job: _Job) -> str:
        """Set the goal's final state; returns the result's message."""
        if job.cancel and goal_handle.is_cancel_requested:
            goal_handle.canceled()
        elif job.error or job.cancel:
            goal_handle.abort()
        else:
            goal_handle.succeed()
        return job.error or ("cancelled" if job.cancel else "")

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        req = _ResetRequest()
        with self._cv:
            if self._goal_reserved or self._reset is not None:
                response.success, response.message = (
                    False,
                    "a run_activations sequence, run_trajectory or reset is in progress",
                )
                return response
            if not self._running:
                response.success, response.message = False, "rig is not running"
                return response
            self._reset = req
            self._cv.notify_all()
        if not req.done.wait(60.0):
            response.success, response.message = False, "reset timed out"
            return response
        response.success, response.message = req.success, req.message
        return response

    # The tick loop -----------------------------------------------------------------------------------

    def _loop(self) -> None:
        while True:
            with self._cv:
                while self._running and self._pacing is Pacing.ON_DEMAND and not self._has_work():
                    self._burst = None
                    if not self._cv.wait(IDLE_CLOCK_PERIOD_S):
                        self._outbox.put(_Outgoing(None, True))  # the clock, for nodes started since
                if not self._running:
                    return
                reset, self._reset = self._reset, None
                job, activation = (None, None) if reset is not None else self._next_activation()
                idle_next = self._idle_after(job)
            try:
                if reset is not None:
                    self._do_reset(reset)
                    continue
                sample = self._plant.step(activation)
            except Exception as err:  # the plant failed: drop to baseline, fail the goal, report
                self._fault(err, job)
                continue
            self._pace(sample.t_s)
            error, self._publish_error = self._publish_error, None
            if error is not None:  # publishing failed: a fault like the plant's
                self._fault(error, job)
                continue
            self._ticks += 1
            clock = idle_next or self._ticks % self._config.clock_period_ticks == 0
            then = self._advance(job, sample) if job is not None else None
            self._outbox.put(_Outgoing(sample, clock, then))

    def _has_work(self) -> bool:
        return self._job is not None or self._reset is not None or bool(self._lockstep)

    def _next_activation(self) -> tuple[_Job | None, np.ndarray]:
        """The sequence or trajectory being played, if any, and the coming tick's activation (lock held)."""
        job = self._job
        if job is not None and not job.cancel:
            try:
                return job, job.next_activation()
            except ValueError as err:  # closed loop: no valid activation; end it, baseline from this tick
                job.error = f"no valid activation for tick {len(job.samples)}: {err}"
                self._log.error(f"run_trajectory aborted: {job.error}")
                self._finish(job)
                return None, self._gate.stop()
        if job is not None:  # cancelled: end the goal now, baseline from this tick on
            self._finish(job)
            return None, self._gate.stop()
        if self._lockstep:
            return None, self._lockstep.popleft()
        return None, self._gate.next_activation()

    def _idle_after(self, job: _Job | None) -> bool:
        """Whether the loop idles after the coming tick (lock held): its /clock must then go out."""
        if self._pacing is not Pacing.ON_DEMAND:
            return False
        if job is not None:
            return len(job.samples) + 1 == job.ticks_total
        return not self._lockstep

    def _advance(self, job: _Job, sample: TickSample) -> Callable[[], None] | None:
        """Add the tick to the goal; after its last tick, what ends it once that tick is published."""
        job.samples.append(sample)
        if len(job.samples) < job.ticks_total:
            return None
        with self._cv:
            self._release(job)
            self._gate.stop()  # the goal is over: baseline until the next command
        return job.done.set

    def _release(self, job: _Job) -> None:
        """The loop plays `job` no more (lock held)."""
        if self._job is job:
            self._job = None

    def _finish(self, job: _Job) -> None:
        self._release(job)
        job.done.set()

    def _do_reset(self, req: _ResetRequest) -> None:
        try:
            sample = self._plant.reset()
        except Exception as err:
            req.success, req.message = False, f"reset failed: {err}"
            self._fault(err, None)
        else:
            self._gate.stop()
            req.success, req.message = True, "at rest"
            self._outbox.put(_Outgoing(sample, True, req.done.set))
            return
        req.done.set()

    def _fault(self, err: Exception, job: _Job | None) -> None:
        self._faults += 1
        self._log.error(f"plant fault: {type(err).__name__}: {err}")
        with self._cv:
            self._gate.stop()
            if job is not None:
                job.error = f"plant fault: {err}"
                self._finish(job)
        if self._on_fault is not None:
            self._on_fault(err)

    def _pace(self, t_s: float) -> None:
        if self._pacing is Pacing.WALL_CLOCK:
            delay = self._wall_start + t_s - time.monotonic()
        elif self._pacing is Pacing.ON_DEMAND and self._config.fast_max_real_time_factor > 0:
            if self._burst is None:
                self._burst = (time.monotonic(), t_s)
            wall0, t0 = self._burst
            delay = wall0 + (t_s - t0) / self._config.fast_max_real_time_factor - time.monotonic()
        else:
            return
        if delay > 0:
            time.sleep(delay)

    def _stamp(self, t_s: float) -> float:
        return t_s + self._stamp_offset_s

    def _publish_loop(self) -> None:
        """Publish queued ticks in order until the None that `stop` queues; then ends what waits on them."""
        dead = False  # the context went down: the owner makes the plant safe; only release the waiters
        while (item := self._outbox.get()) is not None:
            if not dead:
                try:
                    if item.sample is None:
                        self._publish_clock()
                        continue
                    self._publish(item.sample, item.clock)
                except Exception as err:
                    dead = not self._node.context.ok()
                    if not dead:
                        self._publish_error = err
            if item.then is not None:
                item.then()

    def _publish_clock(self) -> None:
        if self._pub_clock is not None and self._last_clock_ns is not None:
            self._pub_clock.publish(Clock(clock=time_from_ns(self._last_clock_ns)))

    def _publish(self, sample: TickSample, clock: bool = True) -> None:
        ns = stamp_ns(self._stamp(sample.t_s))
        self._last_clock_ns = ns
        joints, treadmill, power, applied = self._serializer.serialize(sample, ns)
        if self._pub_clock is not None and clock:
            self._pub_clock.publish(Clock(clock=time_from_ns(ns)))
        self._pub_joints.publish(joints)
        self._pub_treadmill.publish(treadmill)
        self._pub_power.publish(power)
        self._pub_applied.publish(applied)
        self._published += 1
        if self._published % self._config.diagnostics_period_ticks == 0:
            self._publish_diagnostics(time_from_ns(ns))

    def _publish_diagnostics(self, stamp: Time) -> None:
        c = self._gate.counters
        values = {
            "ticks": self._published,
            "commands_accepted": c.accepted,
            "commands_clamped": c.clamped,
            "commands_rejected": c.rejected,
            "commands_ignored_during_sequence": self._ignored_commands,
            "commands_stale": self._stale_commands,
            "watchdog_trips": c.watchdog_trips,
            "plant_faults": self._faults,
        }
        status = DiagnosticStatus(
            level=DiagnosticStatus.OK if self._faults == 0 else DiagnosticStatus.WARN,
            name=f"{self._node.get_fully_qualified_name()}: rig",
            hardware_id=type(self._plant).__name__,
            message="ok" if self._faults == 0 else f"{self._faults} plant faults",
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()],
        )
        self._pub_diag.publish(DiagnosticArray(header=Header(stamp=stamp), status=[status]))

    def _warn(self, kind: str, text: str) -> None:
        now = time.monotonic()
        if now - self._last_log[kind] >= self._config.log_period_s:
            self._last_log[kind] = now
            self._log.warning(text)

    @property
    def counters(self) -> dict[str, int]:
        """Command counters since start (accepted, clamped, rejected, ignored, stale, watchdog trips)."""
        c = self._gate.counters
        return {
            "accepted": c.accepted,
            "clamped": c.clamped,
            "rejected": c.rejected,
            "ignored": self._ignored_commands,
            "stale": self._stale_commands,
            "watchdog_trips": c.watchdog_trips,
        }
