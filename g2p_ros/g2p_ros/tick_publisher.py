"""The rig's output side: each tick of the loop published as the rig contract's four messages.

A thread of its own publishes the ticks the loop hands over (g2p.rig.tick_loop.Tick), in order, with one
shared stamp per tick, while the loop steps the next one (MuJoCo steps without the GIL, so stepping and
publishing overlap); it calls each tick's `then` once the tick is published, so that a sequence or reset
is reported done only after its last tick went out. It also publishes /clock (simulators) and, once a
second of rig time, /diagnostics. What the rig's limits did each tick goes on `rig_limits`.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.publisher import Publisher
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from g2p.plant import TickSample, stamp_ns
from g2p.rig.envelope import EnvelopeAction
from g2p.rig.tick_loop import Tick
from g2p_interfaces.msg import MotorActivation, MotorPower, RigLimits, Treadmill
from g2p_ros import contract
from g2p_ros.convert import time_from_ns
from g2p_ros.tick_serializer import TickSerializer

# Ticks the loop may run ahead of the publisher before it waits (3 s of rig time at 78 Hz).
_OUTBOX_TICKS = 256


class TickPublisher:
    """Publishes a rig's ticks on `node`: joint_states, treadmill, motor_power, applied_activation.

    Args:
        node: the node to create the publishers on.
        hardware_id: the plant's name, in /diagnostics.
        status: the rig's values for /diagnostics (name -> value; "plant_faults" and "trip" set the level).
        sim_time: stamp ticks with the plant's own clock from 0 (simulation time); otherwise with system
            time.
        publish_clock: publish the stamps on /clock (simulators).
        clock_period_ticks: ticks between /clock messages; a tick after which the rig's time stands
            still (`Tick.idles_after`) always goes out.
        diagnostics_period_ticks: ticks between /diagnostics messages.
    """

    def __init__(
        self,
        node: Node,
        hardware_id: str,
        status: Callable[[], dict[str, int | str]],
        sim_time: bool,
        publish_clock: bool,
        clock_period_ticks: int,
        diagnostics_period_ticks: int,
    ) -> None:
        self._node = node
        self._hardware_id = hardware_id
        self._status = status
        self._sim_time = sim_time
        self._clock_period_ticks = clock_period_ticks
        self._diagnostics_period_ticks = diagnostics_period_ticks
        self.published = 0
        """Ticks published (publisher thread)."""
        self.last_stamp_ns: int | None = None
        """The rig's clock: the last tick's stamp, or the start's (publisher thread)."""
        self._stamp_offset_s = 0.0
        self._outbox: queue.Queue[Tick | None] = queue.Queue(maxsize=_OUTBOX_TICKS)
        self._thread: threading.Thread | None = None
        self._error: Exception | None = None  # raised in the thread, a fault of the loop's
        qos = contract.SAMPLE_QOS
        self._pub_joints = node.create_publisher(JointState, contract.JOINT_STATES, qos)
        self._pub_treadmill = node.create_publisher(Treadmill, contract.TREADMILL, qos)
        self._pub_power = node.create_publisher(MotorPower, contract.MOTOR_POWER, qos)
        self._pub_applied = node.create_publisher(MotorActivation, contract.APPLIED_ACTIVATION, qos)
        self._pub_limits = node.create_publisher(RigLimits, contract.RIG_LIMITS, qos)
        self._serializer = TickSerializer()  # publishes serialized messages: cheaper, see its docstring
        self._pub_clock = (
            node.create_publisher(Clock, "/clock", contract.CLOCK_QOS) if publish_clock else None
        )
        self._pub_diag = node.create_publisher(DiagnosticArray, "/diagnostics", contract.DIAGNOSTICS_QOS)

    def start(self, rest: TickSample) -> None:
        """Start the clock at the rest sample's time and the publisher thread.

        The rest sample itself is not published, only its stamp on /clock: published before any
        subscriber could match, it would reach each subscriber on some topics and not others.
        """
        self._stamp_offset_s = 0.0 if self._sim_time else time.time() - rest.t_s
        self.last_stamp_ns = self.tick_stamp_ns(rest.t_s)
        self._publish_clock()
        self._thread = threading.Thread(target=self._run, name="rig_publisher", daemon=True)
        self._thread.start()

    def tick_stamp_ns(self, t_s: float) -> int:
        """The stamp of a tick that ended at `t_s` on the plant's clock (ns)."""
        return stamp_ns(t_s + self._stamp_offset_s)

    def enqueue(self, tick: Tick) -> None:
        """Queue a tick (the loop's receiver); raises the publishing error of an earlier tick, if any."""
        error, self._error = self._error, None
        if error is not None:
            raise error
        self._outbox.put(tick)

    def stop(self, flush_timeout_s: float) -> None:
        """Publish what is queued, end the thread, then wait for every subscriber's acknowledgements.

        Args:
            flush_timeout_s: the longest wait for every subscriber to acknowledge every tick (s): a
                reliable sample lost on the way is resent only while its publisher exists.
        """
        if self._thread is not None:
            self._outbox.put(None)  # after the ticks already queued
            self._thread.join(timeout=5.0)
        log = self._node.get_logger()
        if not self._node.context.ok():
            log.warning("the ROS context is shut down: ticks not yet acknowledged may be lost")
            return
        start = time.monotonic()
        deadline = start + flush_timeout_s
        unacked = [
            p.topic_name
            for p in self._sample_publishers
            if not p.wait_for_all_acked(Duration(seconds=max(0.0, deadline - time.monotonic())))
        ]
        if unacked:
            log.warning(
                f"stopping with ticks not acknowledged after {flush_timeout_s:g} s on "
                f"{', '.join(unacked)}: a subscriber (the recorder?) may miss them"
            )
        elif time.monotonic() - start > 0.01:
            log.info(f"waited {time.monotonic() - start:.2f} s for subscribers to acknowledge the last ticks")

    def destroy(self) -> None:
        """Destroy the publishers (after `stop`)."""
        for publisher in (*self._sample_publishers, self._pub_clock, self._pub_diag):
            if publisher is not None:
                self._node.destroy_publisher(publisher)

    @property
    def _sample_publishers(self) -> tuple[Publisher, ...]:
        return (self._pub_joints, self._pub_treadmill, self._pub_power, self._pub_applied, self._pub_limits)

    def _run(self) -> None:
        """Publish queued ticks in order until the None that `stop` queues; then end what waits on them."""
        dead = False  # the context went down: the owner makes the plant safe; only release the waiters
        while (tick := self._outbox.get()) is not None:
            if not dead:
                try:
                    if tick.sample is None:
                        self._publish_clock()
                    else:
                        clock = tick.idles_after or tick.number % self._clock_period_ticks == 0
                        self._publish(tick.sample, clock)
                        if tick.envelope is not None:
                            self._publish_limits(tick.envelope, tick.trip)
                except Exception as err:
                    dead = not self._node.context.ok()
                    if not dead:
                        self._error = err
            if tick.then is not None:
                tick.then()

    def _publish_clock(self) -> None:
        if self._pub_clock is not None and self.last_stamp_ns is not None:
            self._pub_clock.publish(Clock(clock=time_from_ns(self.last_stamp_ns)))

    def _publish(self, sample: TickSample, clock: bool) -> None:
        ns = self.tick_stamp_ns(sample.t_s)
        self.last_stamp_ns = ns
        joints, treadmill, power, applied = self._serializer.serialize(sample, ns)
        if self._pub_clock is not None and clock:
            self._pub_clock.publish(Clock(clock=time_from_ns(ns)))
        self._pub_joints.publish(joints)
        self._pub_treadmill.publish(treadmill)
        self._pub_power.publish(power)
        self._pub_applied.publish(applied)
        self.published += 1
        if self.published % self._diagnostics_period_ticks == 0:
            self._publish_diagnostics(time_from_ns(ns))

    def _publish_limits(self, action: EnvelopeAction, trip: str) -> None:
        """The tick's RigLimits, stamped as its samples (after `_publish`)."""
        assert self.last_stamp_ns is not None
        self._pub_limits.publish(
            RigLimits(
                header=Header(stamp=time_from_ns(self.last_stamp_ns)),
                commanded=action.commanded,
                joint_scale=action.joint_scale,
                ramp_cap=action.ramp_cap,
                thermal_scale=action.thermal_scale,
                winding_estimate_c=action.winding_c,
                tension_estimate_n=action.tension_n,
                slack_loop_estimate_m=action.slack_loop_m,
                trip=trip,
            )
        )

    def _publish_diagnostics(self, stamp: Time) -> None:
        values = {"ticks": self.published, **self._status()}
        faults, trip = values.get("plant_faults", 0), values.get("trip", "")
        if trip:
            level, message = DiagnosticStatus.ERROR, f"tripped: {trip}"
        elif faults:
            level, message = DiagnosticStatus.WARN, f"{faults} plant faults"
        else:
            level, message = DiagnosticStatus.OK, "ok"
        status = DiagnosticStatus(
            level=level,
            name=f"{self._node.get_fully_qualified_name()}: rig",
            hardware_id=self._hardware_id,
            message=message,
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()],
        )
        self._pub_diag.publish(DiagnosticArray(header=Header(stamp=stamp), status=[status]))
