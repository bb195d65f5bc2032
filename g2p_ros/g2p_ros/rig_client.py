"""Client side of the rig contract: play sequences and closed-loop trajectories, reset, over ROS 2.

`RigClient` implements the core's `g2p.rig.Rig` protocol, so the learner drives a rig on the ROS graph
(simulator or hardware, chosen by remapping) exactly as it drives an in-process plant. Its calls block,
so make them from a thread the node's executor is not using (e.g. an action's execute callback in a
MultiThreadedExecutor); the executor completes the futures in its other threads.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.client import Client
from rclpy.node import Node
from rclpy.task import Future
from std_srvs.srv import Trigger

from g2p.plant import N_JOINTS, NOMINAL_TICK_HZ, Recording
from g2p.rig import RigBusy, RigCancelled, RigError, RigUnreachable
from g2p.rig.closed_loop import TrackedRecording, Trajectory
from g2p.safety import check_activation_sequence
from g2p_interfaces.action import RunActivations, RunTrajectory
from g2p_ros import contract
from g2p_ros.action_client import ActionClient
from g2p_ros.convert import recording_from_msg, trajectory_from_goal, trajectory_goal
from g2p_ros.spinner import wait_for_future

# How long the rig may take to accept a goal (s): a sequence of minutes is hundreds of kB, resent piece
# by piece over a lossy link, and a fast simulation busy publishing answers late on a loaded machine
# (measured: over 10 s, on one host, with three learning runs sharing 2 cores). A rig that is not there
# is found out by the reset that follows.
GOAL_TIMEOUT_S = 30.0
# Once the rig reported the sequence played, how long its result (all ticks) may take to arrive (s): a
# large message over a lossy link is resent fragment by fragment.
RESULT_TIMEOUT_S = 30.0
# How long a cancel waits for the rig's answer (s): the learner's whole stop must fit in the 5 s that
# `ros2 launch` grants before it escalates.
CANCEL_TIMEOUT_S = 1.0
# What each action plays, for messages.
_NOUN = {contract.RUN_ACTIVATIONS: "sequence", contract.RUN_TRAJECTORY: "trajectory"}


class RigClient:
    """Plays sequences and trajectories on the rig serving the contract's actions in the node's namespace.

    `run_activations` plays activation sequences, `run_trajectory` closed-loop trajectories; `reset`
    returns the rig to rest.

    A rig that goes silent is reported as RigUnreachable, never waited for without bound: while a goal
    plays the rig sends feedback every 0.2 s (`rig.feedback_period_s`), so `silence_s` without any means
    the link or the rig is gone. The goal is then cancelled (the cancel reaches the rig if the link
    returns; the rig drops to baseline at the end of the goal anyway) and its late result, if any, is
    ignored.

    Args:
        node: the node to create the clients on (its executor must be spinning in another thread).
        server_timeout_s: how long to wait for the rig to appear before each call (s).
        silence_s: longest wait between two feedback messages while a goal plays (s).
        reset_timeout_s: longest wait for a reset to complete (s); the hardware's reset takes seconds.
    """

    def __init__(
        self,
        node: Node,
        server_timeout_s: float = 10.0,
        silence_s: float = 2.0,
        reset_timeout_s: float = 30.0,
    ) -> None:
        self._node = node
        self._server_timeout_s = server_timeout_s
        self._silence_s = silence_s
        self._reset_timeout_s = reset_timeout_s
        group = ReentrantCallbackGroup()
        action = contract.action_name(node, contract.RUN_ACTIVATIONS)
        self._action = ActionClient(node, RunActivations, action, callback_group=group)
        trajectory_action = contract.action_name(node, contract.RUN_TRAJECTORY)
        self._trajectory_action = ActionClient(node, RunTrajectory, trajectory_action, callback_group=group)
        self._reset = node.create_client(Trigger, contract.RESET, callback_group=group)
        self._action_watch = contract.ServerWatch(action, self._action.server_is_ready)
        self._trajectory_watch = contract.ServerWatch(
            trajectory_action, self._trajectory_action.server_is_ready
        )
        self._reset_watch = contract.ServerWatch(self._reset.srv_name, self._reset.service_is_ready)

    @property
    def watches(self) -> tuple[contract.ServerWatch, contract.ServerWatch]:
        """The rig's run_activations action and reset service, for waiting on them with other servers.

        Not `run_trajectory`: open loop needs only these two, and a learner started with only these two
        remapped (`-r run_activations:=... -r reset:=...`) must still find its rig; `play_trajectory`
        waits for run_trajectory itself.
        """
        return self._action_watch, self._reset_watch

    def destroy(self) -> None:
        """Destroy the clients."""
        self._action.destroy()
        self._trajectory_action.destroy()
        self._node.destroy_client(self._reset)

    def reset(self) -> None:
        """Return the rig to its resting posture.

        Raises:
            RigUnreachable: the rig is not on the graph or did not answer within `reset_timeout_s`.
            RigBusy: the rig refused because a sequence still plays.
            RigError: the reset failed on the rig.
        """
        call_reset(self._reset, self._reset_watch, self._server_timeout_s, self._reset_timeout_s)

    def play(
        self,
        activations: np.ndarray,
        progress: Callable[[int, int], None] | None = None,
        cancel: threading.Event | None = None,
    ) -> Recording:
        """Play an activation sequence (N, 3) at the rig's tick rate and return the recorded ticks.

        Args:
            activations: shape (N, 3), finite, in [0, 1].
            progress: called with (ticks done, ticks total) as feedback arrives.
            cancel: when set, the sequence is cancelled on the rig (motors to baseline) and RigCancelled
                is raised.

        Raises:
            RigUnreachable: the rig is not on the graph, or went silent (see the class docstring).
            RigBusy: the rig rejected the goal (it still plays another sequence).
            RigError: the rig stopped early.
            RigCancelled: `cancel` was set.
        """
        seq = check_activation_sequence(activations)
        result = self._run_goal(
            self._action,
            self._action_watch,
            contract.RUN_ACTIVATIONS,
            RunActivations.Goal(activation=seq.ravel()),
            len(seq),
            progress,
            cancel,
        )
        return self._recording(result, len(seq))

    def play_trajectory(
        self,
        trajectory: Trajectory,
        progress: Callable[[int, int], None] | None = None,
        cancel: threading.Event | None = None,
    ) -> TrackedRecording:
        """Play a trajectory in closed loop, the map evaluated by the rig every tick (g2p.rig.closed_loop).

        The goal is checked here as the rig checks it, so that a goal the rig would reject (which it can
        only log) raises with the reason instead.

        Args:
            trajectory: desired kinematics, map, feedback settings and lead.
            progress: called with (ticks done, ticks total) as feedback arrives.
            cancel: when set, the trajectory is cancelled on the rig (motors to baseline) and RigCancelled
                is raised.

        Raises:
            ValueError: the rig would reject the goal (the message says why; nothing was sent).
            RigUnreachable: the rig is not on the graph, or went silent (see the class docstring).
            RigBusy: the rig rejected the goal (it still plays another goal).
            RigError: the rig stopped early.
            RigCancelled: `cancel` was set.
        """
        goal = trajectory_goal(trajectory)
        n = len(trajectory_from_goal(goal))  # the rig's own validation
        result = self._run_goal(
            self._trajectory_action,
            self._trajectory_watch,
            contract.RUN_TRAJECTORY,
            goal,
            n,
            progress,
            cancel,
        )
        recording = self._recording(result, n)
        correction = np.asarray(result.correction_rad_s, dtype=np.float64)
        if correction.size != n * N_JOINTS:
            raise RigError(f"{contract.RUN_TRAJECTORY}: {correction.size} correction values for {n} ticks")
        return TrackedRecording(recording, correction.reshape(n, N_JOINTS))

    def _run_goal(
        self,
        client: ActionClient,
        watch: contract.ServerWatch,
        name: str,
        goal: Any,
        ticks: int,
        progress: Callable[[int, int], None] | None,
        cancel: threading.Event | None,
    ) -> Any:
        """Send a goal of `ticks` ticks and wait for its result, reporting silence, cancel and refusal.

        Returns:
            The action's result message (whatever its status: the caller checks the ticks).
        """
        if not watch.wait_until_ready(self._server_timeout_s):
            raise RigUnreachable(f"no rig serves {name} within {self._server_timeout_s} s")
        heard = [time.monotonic(), 0]  # when the rig last gave word, and the ticks it reported done

        def on_feedback(msg: Any) -> None:
            heard[:] = [time.monotonic(), int(msg.feedback.ticks_done)]
            if progress is not None:
                progress(int(msg.feedback.ticks_done), int(msg.feedback.ticks_total))

        send = client.send_goal_async(goal, feedback_callback=on_feedback)
        handle: Any = _wait(send, GOAL_TIMEOUT_S, f"the {name} goal")
        if not handle.accepted:
            # The goal was checked here already: the rig refuses only while it is busy.
            raise RigBusy(f"the rig rejected the {name} goal: another sequence or a reset runs")
        heard[0] = time.monotonic()
        result_future = handle.get_result_async()
        # Worst case the rig plays in real time; add a margin for slow machines.
        limit_s = 60.0 + 3.0 * ticks / NOMINAL_TICK_HZ
        deadline = time.monotonic() + limit_s
        while not wait_for_future(result_future, 0.05, cancel):
            if cancel is not None and cancel.is_set():
                # Not waited for without bound: a rig stopped by the same signal (`ros2 launch` signals
                # every node at once) never answers. Answered or not, the rig ends at baseline.
                answered = wait_for_future(handle.cancel_goal_async(), CANCEL_TIMEOUT_S)
                raise RigCancelled(
                    f"{_NOUN[name]} cancelled" + ("" if answered else " (the rig did not answer the cancel)")
                )
            quiet_s = time.monotonic() - heard[0]
            playing = heard[1] < ticks
            if (playing and quiet_s > self._silence_s) or quiet_s > RESULT_TIMEOUT_S:
                handle.cancel_goal_async()  # best effort: reaches the rig if the link returns
                raise RigUnreachable(
                    f"no word from the rig for {quiet_s:.1f} s after {heard[1]} of {ticks} ticks "
                    f"(link down or rig gone); the {_NOUN[name]} is abandoned"
                )
            if time.monotonic() > deadline:
                raise RigError(f"{name} did not finish within {limit_s:.0f} s")
        response = result_future.result()
        if response is None:
            raise RigError(f"{name} returned no result")
        return response.result

    @staticmethod
    def _recording(result: Any, ticks: int) -> Recording:
        recording = recording_from_msg(result.samples)
        if len(recording) != ticks:
            raise RigError(f"rig played {len(recording)} of {ticks} ticks: {result.message}")
        return recording


def call_reset(
    client: Client, watch: contract.ServerWatch, server_timeout_s: float, timeout_s: float
) -> None:
    """Call the rig's reset service and wait until the rig is at rest (RigClient.reset, TickPlant.reset).

    Args:
        client: the Trigger client of the rig's reset service.
        watch: its ServerWatch.
        server_timeout_s: how long to wait for the service to appear (s).
        timeout_s: longest wait for the reset to complete (s).

    Raises:
        RigUnreachable: the rig is not on the graph or did not answer within `timeout_s`.
        RigBusy: the rig refused because a sequence still plays.
        RigError: the reset failed on the rig.
    """
    if not watch.wait_until_ready(server_timeout_s):
        raise RigUnreachable(f"no rig answers {watch.name} within {server_timeout_s} s")
    response: Any = _wait(client.call_async(Trigger.Request()), timeout_s, "reset")
    if not response.success:
        if "in progress" in response.message:
            raise RigBusy(f"rig reset refused: {response.message}")
        raise RigError(f"rig reset failed: {response.message}")


def _wait(future: Future, timeout_s: float, what: str) -> object:
    if not wait_for_future(future, timeout_s):
        raise RigUnreachable(f"no answer to {what} within {timeout_s:g} s")
    if future.exception() is not None:
        raise RigError(f"{what} failed: {future.exception()}")
    return future.result()
