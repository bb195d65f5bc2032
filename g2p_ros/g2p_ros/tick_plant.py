"""`TickPlant`: the rig contract as a `g2p.plant.Plant`, one tick per `step` through `activation_cmd`.

A policy written for an in-process plant (a Gymnasium environment of g2p.rl.envs, say) drives the simulator
node or the hardware driver with it, chosen by remapping or the node's namespace. Each `step` publishes one
command stamped with the node's clock and returns the first tick the rig publishes stamped after it,
built from that tick's four messages; its `activation` is the rig's `applied_activation` (after clamping,
baseline, watchdog and the rig's safety envelope), not the command. The tick's `rig_limits` message says
whether the rig tripped: `fault` is its reason, as an in-process `MujocoLeg`'s, so a Gymnasium environment
over this plant terminates on a trip as over the in-process rig.

Timing (docs/RL.md): in fast simulation every command plays exactly one tick (lockstep), so the tick
returned is the one the command played. In real time (the hardware, or the simulator in realtime mode)
the rig ticks at 78 Hz on its own and decides each tick's activation at the tick's start: a command plays
from the tick after the one during which it arrives, so the tick returned (the first stamped after the
command) shows the previous step's command, and a policy that does not answer within the rig's watchdog
(3 ticks, about 38 ms) finds the motors dropped to baseline.

As for RigClient, the caller owns the node and spins its executor in another thread; `reset` and `step`
block, so call them from a thread the executor does not use.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from typing import Any

import numpy as np
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Header
from std_srvs.srv import Trigger

from g2p.plant import NOMINAL_TICK_HZ, FloatArray, TickSample
from g2p.rig import RigError, RigUnreachable
from g2p.safety import BASELINE_ACTIVATION, check_activation
from g2p_interfaces.msg import MotorActivation, MotorPower, RigLimits, Treadmill
from g2p_ros import contract
from g2p_ros.convert import tick_sample
from g2p_ros.rig_client import call_reset

# The rig's four messages per tick, in the order `tick_sample` takes them.
_TOPICS = (
    (contract.JOINT_STATES, JointState),
    (contract.TREADMILL, Treadmill),
    (contract.MOTOR_POWER, MotorPower),
    (contract.APPLIED_ACTIVATION, MotorActivation),
)
# And what the rig's limits did over the tick: a tick is complete with all five.
_PARTS = (*_TOPICS, (contract.RIG_LIMITS, RigLimits))
# Only the newest ticks matter here; a reliable reader of this depth rides out this process's pauses.
_TICK_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
# Ticks kept once complete (about 3 s at 78 Hz), and incomplete ones (a topic behind the others).
_KEEP_TICKS = 256
# A tick that comes after a command but is stamped this long before it is on another clock (s): the rig
# itself ignores commands this old (rig.command_max_age_s).
_CLOCK_TOLERANCE_S = 0.5


class TickPlant:
    """The rig serving the contract in the node's namespace (default /leg), stepped one tick at a time.

    The command is stamped with the node's clock: run the node with `use_sim_time` when the rig stamps in
    simulation time (the simulator in fast time mode publishes it on /clock), as the learner does; the rig
    ignores commands stamped more than `rig.command_max_age_s` (0.5 s) before its own time.

    Args:
        node: the node to create the publisher, subscriptions and reset client on; its executor must be
            spinning in another thread.
        tick_hz: the rig's nominal tick rate (Hz), reported as `tick_hz`.
        server_timeout_s: how long to wait for the rig to appear before a call (s).
        tick_timeout_s: longest wait for a step's tick (s); longer means the rig is gone.
        reset_timeout_s: longest wait for a reset to complete (s); the hardware's reset takes seconds.
    """

    def __init__(
        self,
        node: Node,
        tick_hz: float = NOMINAL_TICK_HZ,
        server_timeout_s: float = 10.0,
        tick_timeout_s: float = 5.0,
        reset_timeout_s: float = 30.0,
    ) -> None:
        self._node = node
        self._tick_hz = tick_hz
        self._server_timeout_s = server_timeout_s
        self._tick_timeout_s = tick_timeout_s
        self._reset_timeout_s = reset_timeout_s
        self._cv = threading.Condition()
        self._parts: dict[int, dict[str, Any]] = {}  # stamp (ns) -> topic -> message, until all five came
        # (number, ns, sample, trip) of the newest complete ticks
        self._ticks: deque[tuple[int, int, TickSample, str]] = deque(maxlen=_KEEP_TICKS)
        self._fault = ""
        self._completed = 0  # ticks completed so far
        self._newest_ns = -1  # stamp of the newest complete tick
        self._bad = ""  # why the last malformed tick was dropped
        self._closed = False
        group = ReentrantCallbackGroup()
        self._cmd = node.create_publisher(MotorActivation, contract.ACTIVATION_CMD, contract.COMMAND_QOS)
        self._subs = [
            node.create_subscription(msg_type, name, self._collector(name), _TICK_QOS, callback_group=group)
            for name, msg_type in _PARTS
        ]
        self._reset = node.create_client(Trigger, contract.RESET, callback_group=group)
        self._topics_watch = contract.ServerWatch(
            f"{self._cmd.topic_name} and the rig's tick topics",
            lambda: (
                self._cmd.get_subscription_count() > 0
                and all(sub.get_publisher_count() > 0 for sub in self._subs)
            ),
        )
        self._reset_watch = contract.ServerWatch(
            node.resolve_service_name(contract.RESET), self._reset.service_is_ready
        )

    @property
    def tick_hz(self) -> float:
        """Nominal tick rate (Hz)."""
        return self._tick_hz

    @property
    def fault(self) -> str:
        """Why the rig was tripped after the last tick returned (a limit's reason; "" when it was not)."""
        return self._fault

    def reset(self) -> TickSample:
        """Reset the rig to rest (waiting until it is), then play one baseline tick and return it.

        The rig's own rest sample cannot be told apart on its topics (it repeats the stamp of the tick
        before the reset), so the sample returned is the first baseline tick after it: the leg at rest.
        A step skips the rest sample because its stamp is not after that tick's, which this plant saw or
        the node's clock (/clock, in simulation time) already shows.

        Raises:
            RigUnreachable: the rig is not on the graph, or did not answer within the timeouts.
            RigBusy: a run_activations or run_trajectory goal still plays on the rig.
            RigError: the reset failed on the rig.
        """
        pending = contract.wait_all([self._reset_watch, self._topics_watch], self._server_timeout_s)
        if pending:
            raise RigUnreachable(f"no rig serves {', '.join(pending)} within {self._server_timeout_s} s")
        call_reset(self._reset, self._reset_watch, self._server_timeout_s, self._reset_timeout_s)
        return self.step(np.full(3, BASELINE_ACTIVATION))

    def step(self, activation: FloatArray) -> TickSample:
        """Command `activation` and return the first tick stamped after the command.

        Args:
            activation: shape (3,), finite; the rig clamps it to [baseline, 1].

        Raises:
            ValueError: not 3 finite numbers (nothing is published).
            RigUnreachable: the rig is not on the graph, or no tick came within `tick_timeout_s`.
            RigError: ticks come, but stamped on another clock than the node's (see the class docstring).
        """
        a = check_activation(activation)
        if self._closed:
            raise RigError("the TickPlant is closed")
        if not self._topics_watch.poll() and not self._topics_watch.wait_until_ready(self._server_timeout_s):
            raise RigUnreachable(f"no rig serves {self._topics_watch.name} within {self._server_timeout_s} s")
        with self._cv:
            number, newest_ns = self._completed, self._newest_ns
        now = self._node.get_clock().now()
        self._cmd.publish(MotorActivation(header=Header(stamp=now.to_msg()), activation=a.tolist()))
        return self._tick_after(number, max(newest_ns, now.nanoseconds), now.nanoseconds)

    def close(self) -> None:
        """Command baseline once and destroy the publisher, subscriptions and client.

        The rig applies baseline from the tick during which the command arrives (in fast simulation it
        plays it as one more tick); were it lost, the rig's watchdog drops to baseline within 3 ticks.
        """
        if self._closed:
            return
        self._closed = True
        if self._node.context.ok():
            stamp = self._node.get_clock().now().to_msg()
            self._cmd.publish(
                MotorActivation(header=Header(stamp=stamp), activation=[BASELINE_ACTIVATION] * 3)
            )
            self._cmd.wait_for_all_acked(Duration(seconds=1.0))
        self._node.destroy_publisher(self._cmd)
        for sub in self._subs:
            self._node.destroy_subscription(sub)
        self._node.destroy_client(self._reset)

    def _tick_after(self, number: int, after_ns: int, command_ns: int) -> TickSample:
        """The first tick completed after tick `number` and stamped after `after_ns`."""
        deadline = time.monotonic() + self._tick_timeout_s
        with self._cv:
            while True:
                for k, ns, sample, trip in self._ticks:
                    if k > number and ns > after_ns:
                        self._fault = trip
                        return sample
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                self._cv.wait(left)
            heard = [ns for k, ns, _, _ in self._ticks if k > number]
            partial = {ns: sorted(parts) for ns, parts in self._parts.items() if ns > after_ns}
        if heard and max(heard) < command_ns - _CLOCK_TOLERANCE_S * 1e9:
            raise RigError(
                f"{len(heard)} ticks came after the command, all stamped long before it (newest "
                f"{max(heard) * 1e-9:.3f} s, command {command_ns * 1e-9:.3f} s): the node's clock is not the "
                "rig's; set use_sim_time when the rig runs on simulation time (/clock)"
            )
        why = f"; a malformed tick was dropped: {self._bad}" if self._bad else ""
        if partial:  # where it stalls: a tick's messages that did come
            ns = min(partial)
            why += f"; of the tick stamped {ns * 1e-9:.6f} s only {', '.join(partial[ns])} came"
        raise RigUnreachable(f"no tick from the rig within {self._tick_timeout_s:g} s of a command{why}")

    def _collector(self, topic: str) -> Any:
        def collect(msg: Any) -> None:
            ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            with self._cv:
                parts = self._parts.setdefault(ns, {})
                parts[topic] = msg
                if len(parts) < len(_PARTS):
                    while len(self._parts) > _KEEP_TICKS:  # a topic that never comes: forget the oldest
                        del self._parts[min(self._parts)]
                    return
                del self._parts[ns]
                try:
                    sample = tick_sample(*(parts[name] for name, _ in _TOPICS))
                except ValueError as err:
                    self._bad = str(err)
                    return
                self._completed += 1
                self._newest_ns = max(self._newest_ns, ns)
                self._ticks.append((self._completed, ns, sample, str(parts[contract.RIG_LIMITS].trip)))
                self._cv.notify_all()

        return collect
