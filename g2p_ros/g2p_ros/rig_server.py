"""The rig contract served over ROS 2 for any plant: the simulator and the hardware driver share it.

The rig's logic is the core's `g2p.rig.tick_loop.TickLoop`, in its own thread: which activation each tick
plays, pacing, the watchdog, one job or reset at a time. This adapter converts: goals, commands and
resets go in, a `TickPublisher` publishes the ticks; a sequence, trajectory or reset is reported done only
once its last tick is published. Executor callbacks only validate and hand work to the loop.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.action.server import ServerGoalHandle
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.node import Node
from std_srvs.srv import Trigger

from g2p.plant import N_JOINTS, NOMINAL_TICK_HZ, Plant, Recording, TickSample
from g2p.rig.closed_loop import TrajectoryTracker
from g2p.rig.tick_loop import STOPPED, CommandOutcome, Job, Pacing, TickLoop, TickLoopConfig
from g2p.safety import InvalidActivation, check_activation_sequence
from g2p.validation import require
from g2p_interfaces.action import RunActivations, RunTrajectory
from g2p_interfaces.msg import MotorActivation
from g2p_ros import contract
from g2p_ros.convert import rig_samples_msg, trajectory_from_goal
from g2p_ros.tick_publisher import TickPublisher


@dataclass(frozen=True)
class RigServerConfig(TickLoopConfig):
    """How the rig contract is served: the tick loop's settings (TickLoopConfig) and these.

    Attributes:
        feedback_period_s: wall time between run_activations and run_trajectory feedback messages (s).
        diagnostics_period_ticks: ticks between /diagnostics messages (78 = about 1 s of rig time).
        log_period_s: minimum wall time between two warnings about rejected or ignored commands (s).
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

    feedback_period_s: float = 0.2
    diagnostics_period_ticks: int = round(NOMINAL_TICK_HZ)
    log_period_s: float = 1.0
    clock_period_ticks: int = 1
    command_max_age_s: float = 0.5
    flush_timeout_s: float = 5.0

    def __post_init__(self) -> None:
        super().__post_init__()
        require(
            self.clock_period_ticks >= 1, "clock_period_ticks", f"must be >= 1, got {self.clock_period_ticks}"
        )
        require(self.flush_timeout_s >= 0, "flush_timeout_s", f"must be >= 0, got {self.flush_timeout_s}")
        require(
            self.command_max_age_s >= 0, "command_max_age_s", f"must be >= 0, got {self.command_max_age_s}"
        )


class RigServer:
    """Serves the rig contract for `plant` on `node`, with topics relative to the node's namespace.

    Args:
        node: the node to create publishers, subscriptions, the action and the service on.
        plant: the plant; only the tick loop touches it after `start`.
        pacing: who paces the loop (see Pacing).
        config: the loop's settings and the contract's.
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
        self._config = config
        self._sim_time = sim_time
        self._on_fault = on_fault
        self._log = node.get_logger()
        self._out = TickPublisher(
            node,
            type(plant).__name__,
            self._status,
            sim_time,
            publish_clock,
            config.clock_period_ticks,
            config.diagnostics_period_ticks,
        )
        self._loop = TickLoop(plant, pacing, config, self._out.enqueue, self._fault)
        self._last_log = {"rejected": 0.0, "ignored": 0.0, "stale": 0.0, "tripped": 0.0}
        self._stale_commands = 0
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
        """Reset the plant to rest and start the tick loop and the publisher."""
        first = self._plant.reset()
        self._out.start(first)
        self._loop.start(first.t_s)

    def stop(self) -> None:
        """Stop the loop, abort any sequence or trajectory and leave the plant at baseline (idempotent).

        The last tick published is one at baseline, played after the loop ended: every subscriber (and so
        the bag) sees the rig stop safe. Then every subscriber's acknowledgement of every tick is awaited.
        """
        try:
            if not self._loop.stop():
                return
        except Exception as err:  # a faulted plant: its close() makes it safe
            self._log.error(f"no final baseline tick: {type(err).__name__}: {err}")
        self._out.stop(self._config.flush_timeout_s)
        last = self._out.last_stamp_ns
        self._log.info(
            f"stopped after publishing {self._out.published} ticks, the last at baseline "
            f"(stamp {'none' if last is None else f'{last} ns'})"
        )

    def destroy(self) -> None:
        """Stop and destroy the ROS entities this server created.

        Call it from the thread that spins the node's executor, between two spins, or once nothing spins
        it: rclpy's executor (9.1.2, ros2/rclpy#1385) lists the node's waitables (the action servers, the
        publishers' event handlers) before entering them, and adds one destroyed in between to its wait
        set all the same ("action server pointer is invalid"), ending the spin.
        """
        self.stop()
        self._action.destroy()
        self._trajectory_action.destroy()
        self._out.destroy()
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
        outcome = self._loop.command(msg.activation)
        if outcome is CommandOutcome.IGNORED:
            self._warn(
                "ignored",
                "activation_cmd ignored while a run_activations or run_trajectory goal plays "
                f"({self._loop.counters.ignored_commands} so far)",
            )
        elif outcome is CommandOutcome.TRIPPED:
            self._warn("tripped", f"activation_cmd ignored: the rig is tripped ({self._loop.trip}); reset it")
        elif outcome is CommandOutcome.REJECTED:
            self._warn(
                "rejected",
                f"activation_cmd rejected (needs 3 finite values): {list(msg.activation)} "
                f"({self._loop.gate.counters.rejected} rejected so far)",
            )

    def _command_age_s(self, stamp: Time) -> float | None:
        """How long ago a command was stamped on the rig's clock (s); None when unstamped or unknown."""
        stamp_ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        now_ns = self._out.last_stamp_ns if self._sim_time else time.time_ns()
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
        if not self._loop.reserve():
            self._log.warning(f"{action} goal rejected: another sequence or a reset is in progress")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _on_cancel(self, goal_handle: ServerGoalHandle) -> CancelResponse:
        self._loop.cancel()
        return CancelResponse.ACCEPT

    def _execute(self, goal_handle: ServerGoalHandle) -> RunActivations.Result:
        job = Job(activations=np.asarray(goal_handle.request.activation, dtype=np.float64).reshape(-1, 3))
        samples = self._play(goal_handle, job, RunActivations.Feedback())
        return RunActivations.Result(samples=self._samples_msg(samples), message=self._end(goal_handle, job))

    def _execute_trajectory(self, goal_handle: ServerGoalHandle) -> RunTrajectory.Result:
        job = Job()
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

    def _play(self, goal_handle: ServerGoalHandle, job: Job, feedback: Any) -> list[TickSample]:
        """Hand `job` to the loop, send feedback every period until it ends; returns the ticks played."""
        self._loop.play(job)
        feedback.ticks_total = job.ticks_total
        while True:  # feedback every period while the loop plays, and once at the end
            finished = job.done.wait(self._config.feedback_period_s)
            feedback.ticks_done = len(job.samples)
            goal_handle.publish_feedback(feedback)
            if finished:
                break
        self._loop.release()
        return list(job.samples)

    def _samples_msg(self, samples: list[TickSample]) -> Any:
        stamps = np.array([self._out.tick_stamp_ns(sample.t_s) for sample in samples], dtype=np.int64)
        return rig_samples_msg(Recording.from_samples(samples), stamps)

    def _end(self, goal_handle: ServerGoalHandle, job: Job) -> str:
        """Set the goal's final state; returns the result's message."""
        if job.cancel and goal_handle.is_cancel_requested:
            goal_handle.canceled()
        elif job.error or job.cancel:
            if job.error and job.error != STOPPED:  # a stop is logged once, by stop()
                self._log.error(f"goal aborted: {job.error}")
            goal_handle.abort()
        else:
            goal_handle.succeed()
        return job.error or ("cancelled" if job.cancel else "")

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        req = self._loop.request_reset()
        if isinstance(req, str):
            response.success, response.message = False, req
        elif not req.done.wait(60.0):
            response.success, response.message = False, "reset timed out"
        else:
            response.success, response.message = req.success, req.message
        return response

    # The loop's side ---------------------------------------------------------------------------------

    def _fault(self, err: Exception) -> None:
        self._log.error(f"plant fault: {type(err).__name__}: {err}")
        if self._on_fault is not None:
            self._on_fault(err)

    def _status(self) -> dict[str, int | str]:
        """/diagnostics' values: the counters, the envelope's and the trip's."""
        counters = self.counters
        loop = self._loop
        return {
            "trip": loop.trip,
            "trips": loop.counters.trips,
            "envelope_ticks": loop.counters.envelope_ticks,
            "winding_estimate_c": " ".join(f"{t:.1f}" for t in loop.envelope.winding_c),
            "commands_accepted": counters["accepted"],
            "commands_clamped": counters["clamped"],
            "commands_rejected": counters["rejected"],
            "commands_ignored_during_sequence": counters["ignored"],
            "commands_stale": counters["stale"],
            "watchdog_trips": counters["watchdog_trips"],
            "plant_faults": self._loop.counters.faults,
        }

    def _warn(self, kind: str, text: str) -> None:
        now = time.monotonic()
        if now - self._last_log[kind] >= self._config.log_period_s:
            self._last_log[kind] = now
            self._log.warning(text)

    @property
    def counters(self) -> dict[str, int]:
        """Command counters since start (accepted, clamped, rejected, ignored, stale, watchdog trips)."""
        c = self._loop.gate.counters
        return {
            "accepted": c.accepted,
            "clamped": c.clamped,
            "rejected": c.rejected,
            "ignored": self._loop.counters.ignored_commands,
            "stale": self._stale_commands,
            "watchdog_trips": c.watchdog_trips,
        }
