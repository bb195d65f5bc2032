"""Helpers for the tests of the rig executables (`sim`, `driver`): starting them, and a peer.

The peer is the test's side of the rig contract: every rig topic collected, the action and reset
clients, optionally a RigClient (the learner's side).
"""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from g2p.hardware import WiringConfig
from g2p_interfaces.action import RunActivations, RunTrajectory
from g2p_interfaces.msg import MotorActivation, MotorPower, RigLimits, Treadmill
from g2p_ros import contract
from g2p_ros.action_client import ActionClient
from g2p_ros.rig_client import RigClient
from tests.ros.rosproc import NodeProcess, RosPeer, wait_until

# The leg seed of the `fast_sim` fixture (tests/ros/conftest.py).
FAST_SIM_SEED = 3

BASELINE = 0.15
# Like the recorder: a reader history deep enough to absorb this process's pauses in fast simulation.
DEEP_QOS = QoSProfile(depth=10000, reliability=ReliabilityPolicy.RELIABLE)
PWM = WiringConfig().pwm  # the installed wiring.yaml uses the default map: 10 % .. 90 %
BASELINE_DUTY = PWM.duty(BASELINE)
DUTY_STEP = 1.0 / 4096  # PCA9685 resolution


def start_sim(log_dir: Path, *params: str) -> NodeProcess:
    """The installed `sim`, with parameters `name:=value`."""
    args = ["--ros-args"]
    for p in params:
        args += ["-p", p]
    return NodeProcess("g2p_sim", "sim", args, log_dir)


def start_driver(log_dir: Path, state_dir: Path, *params: str) -> NodeProcess:
    """The installed `driver` on fake devices keeping their state in `state_dir`, with parameters."""
    args = ["--ros-args", "-p", "fake_devices:=true", "-p", f"fake.state_dir:={state_dir}"]
    for p in params:
        args += ["-p", p]
    return NodeProcess("g2p_driver", "driver", args, log_dir)


def outputs(state_dir: Path) -> dict[str, Any]:
    """What the motor drivers see, as the fake rig last wrote it."""
    return json.loads((state_dir / "outputs.json").read_text())  # type: ignore[no-any-return]


def at_baseline(out: dict[str, Any]) -> bool:
    return bool(out["enabled"]) and all(abs(d - BASELINE_DUTY) <= DUTY_STEP for d in out["duty"])


def is_off(out: dict[str, Any]) -> bool:
    return out["enabled"] is False and out["duty"] == [0.0, 0.0, 0.0] and out["activation"] == [0.0] * 3


class RigPeer(RosPeer):
    """The test's side of the rig contract: every rig topic collected, the action and reset clients.

    Args:
        rig_client: also create `client`, a g2p_ros RigClient (the learner's side) on the same node.
        server_timeout_s: the RigClient's wait for the rig's servers before each call (s).
    """

    def __init__(self, rig_client: bool = False, server_timeout_s: float = 10.0) -> None:
        super().__init__("rig_peer")
        self.lock = threading.Lock()
        self.received: dict[str, list[object]] = {
            name: []
            for name in (
                contract.JOINT_STATES,
                contract.TREADMILL,
                contract.MOTOR_POWER,
                contract.APPLIED_ACTIVATION,
                contract.RIG_LIMITS,
            )
        }
        self.diagnostics: list[DiagnosticArray] = []
        for name, msg_type in (
            (contract.JOINT_STATES, JointState),
            (contract.TREADMILL, Treadmill),
            (contract.MOTOR_POWER, MotorPower),
            (contract.APPLIED_ACTIVATION, MotorActivation),
            (contract.RIG_LIMITS, RigLimits),
        ):
            self.node.create_subscription(msg_type, name, self._collector(name), DEEP_QOS)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self.diagnostics.append, 10)
        self.cmd = self.node.create_publisher(MotorActivation, contract.ACTIVATION_CMD, contract.COMMAND_QOS)
        self.action = ActionClient(self.node, RunActivations, contract.RUN_ACTIVATIONS)
        self.trajectory = ActionClient(self.node, RunTrajectory, contract.RUN_TRAJECTORY)
        self.reset = self.node.create_client(Trigger, contract.RESET)
        self.client = RigClient(self.node, server_timeout_s) if rig_client else None
        self.start()

    def destroy_entities(self) -> None:
        self.action.destroy()
        self.trajectory.destroy()
        if self.client is not None:
            self.client.destroy()

    def _collector(self, name: str):
        def collect(msg: Any) -> None:
            with self.lock:
                self.received[name].append(msg)

        return collect

    def applied(self) -> list[list[float]]:
        with self.lock:
            return [list(m.activation) for m in self.received[contract.APPLIED_ACTIVATION]]

    def decided(self) -> list[list[float]]:
        """Each tick's activation as the rig decided it, before its safety envelope (`rig_limits`)."""
        with self.lock:
            return [list(m.commanded) for m in self.received[contract.RIG_LIMITS]]

    def wait_for_rig(self) -> None:
        self.wait_for_servers(
            {
                "run_activations": self.action.server_is_ready,
                "run_trajectory": self.trajectory.server_is_ready,
                "reset": self.reset.service_is_ready,
            },
            30.0,
        )
        wait_until(
            lambda: self.cmd.get_subscription_count() > 0, 30.0, "the rig to subscribe to activation_cmd"
        )

    def play(self, activations: np.ndarray, feedback: list[object] | None = None):
        goal = RunActivations.Goal(activation=np.asarray(activations, dtype=np.float64).ravel())
        handle = self.wait(
            self.action.send_goal_async(
                goal, feedback_callback=(feedback.append if feedback is not None else None)
            ),
            30.0,
        )
        return handle

    def send_trajectory(self, goal: RunTrajectory.Goal, feedback: list[object] | None = None):
        """Send a run_trajectory goal as it is (no checks on this side); returns the goal handle."""
        return self.wait(
            self.trajectory.send_goal_async(
                goal, feedback_callback=(feedback.append if feedback is not None else None)
            ),
            30.0,
        )
