"""The installed `driver` executable on physics-backed fake buses, driven over ROS 2 like a lifecycle manager.

The fake rig keeps its output state (enable line, duty cycles, activations) in outputs.json in a state
directory and reads faults to inject from faults.json there: the test checks what the motor drivers
would see, from outside the driver process.
"""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from action_msgs.msg import GoalStatus
from diagnostic_msgs.msg import DiagnosticArray
from lifecycle_msgs.msg import State, Transition, TransitionEvent
from lifecycle_msgs.srv import ChangeState, GetState
from std_msgs.msg import String
from std_srvs.srv import Trigger

from g2p.plant import Recording
from g2p_interfaces.action import RunActivations
from g2p_interfaces.msg import MotorActivation
from g2p_ros import contract
from g2p_ros.action_client import ActionClient
from g2p_ros.convert import recording_from_msg
from g2p_ros.params import CONFIG_QOS
from tests.ros.rig_nodes import BASELINE, DEEP_QOS, at_baseline, is_off, outputs, start_driver
from tests.ros.rosproc import NodeProcess, RosPeer, wait_until


class LifecyclePeer(RosPeer):
    """A lifecycle manager and a learner-like client of the rig contract, in one test node."""

    def __init__(self) -> None:
        super().__init__("driver_peer")
        self.lock = threading.Lock()
        self.events: list[TransitionEvent] = []
        self.applied: list[list[float]] = []
        self.diagnostics: list[DiagnosticArray] = []
        self.change = self.node.create_client(ChangeState, "driver/change_state")
        self.get = self.node.create_client(GetState, "driver/get_state")
        self.node.create_subscription(TransitionEvent, "driver/transition_event", self._on_event, 10)
        self.node.create_subscription(
            MotorActivation, contract.APPLIED_ACTIVATION, self._on_applied, DEEP_QOS
        )
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diag, 10)
        self.configs: list[dict[str, object]] = []
        self.node.create_subscription(
            String, "driver/config", lambda m: self.configs.append(json.loads(m.data)), CONFIG_QOS
        )
        self.cmd = self.node.create_publisher(MotorActivation, contract.ACTIVATION_CMD, contract.COMMAND_QOS)
        self.action = ActionClient(self.node, RunActivations, contract.RUN_ACTIVATIONS)
        self.reset = self.node.create_client(Trigger, contract.RESET)
        self.start()

    def destroy_entities(self) -> None:
        self.action.destroy()

    def _on_event(self, msg: TransitionEvent) -> None:
        with self.lock:
            self.events.append(msg)

    def _on_applied(self, msg: MotorActivation) -> None:
        with self.lock:
            self.applied.append(list(msg.activation))

    def count_applied(self, activation: list[float]) -> int:
        """How many ticks applied exactly `activation` (3 values)."""
        with self.lock:
            return sum(tick == activation for tick in self.applied)

    def _on_diag(self, msg: DiagnosticArray) -> None:
        with self.lock:
            self.diagnostics.append(msg)

    def wait_for_driver(self) -> None:
        self.wait_for_servers(
            {"change_state": self.change.service_is_ready, "get_state": self.get.service_is_ready}, 30.0
        )

    def transition(self, transition_id: int, timeout_s: float = 60.0) -> bool:
        request = ChangeState.Request(transition=Transition(id=transition_id))
        return bool(self.wait(self.change.call_async(request), timeout_s).success)

    def state(self) -> int:
        return int(self.wait(self.get.call_async(GetState.Request()), 10.0).current_state.id)

    def goal_states(self) -> list[int]:
        with self.lock:
            return [e.goal_state.id for e in self.events]

    def play(self, activations: np.ndarray) -> Any:
        self.wait_for_servers({"run_activations": self.action.server_is_ready}, 30.0)
        goal = RunActivations.Goal(activation=np.asarray(activations, dtype=np.float64).ravel())
        return self.wait(self.action.send_goal_async(goal), 30.0)

    def hardware_status(self) -> dict[str, str] | None:
        with self.lock:
            for msg in reversed(self.diagnostics):
                for status in msg.status:
                    if status.name.endswith(": hardware"):
                        return {kv.key: kv.value for kv in status.values}
        return None


@pytest.fixture
def state_dir(tmp_path: Path) -> Path:
    return tmp_path / "fake_rig"


@pytest.fixture
def peer() -> Iterator[LifecyclePeer]:
    p = LifecyclePeer()
    yield p
    p.close()


@pytest.fixture
def driver(tmp_path: Path, state_dir: Path) -> Iterator[NodeProcess]:
    proc = start_driver(tmp_path, state_dir)
    yield proc
    assert proc.stop() == 0, proc.log_path.read_text()


def test_lifecycle_serves_the_contract_and_leaves_outputs_safe(
    driver: NodeProcess, peer: LifecyclePeer, state_dir: Path
) -> None:
    peer.wait_for_driver()
    assert peer.state() == State.PRIMARY_STATE_UNCONFIGURED
    # The resolved configuration, latched on ~/config for the recorder.
    wait_until(lambda: len(peer.configs) == 1, 10.0, "the driver's configuration")
    assert peer.configs[0]["fake_devices"] is True
    assert peer.configs[0]["rig"]["baseline_activation"] == BASELINE  # type: ignore[index]
    assert peer.transition(Transition.TRANSITION_CONFIGURE), driver.log()
    assert peer.state() == State.PRIMARY_STATE_INACTIVE
    assert is_off(outputs(state_dir))  # configure opens the devices, outputs stay off

    assert peer.transition(Transition.TRANSITION_ACTIVATE), driver.log()
    assert peer.state() == State.PRIMARY_STATE_ACTIVE
    assert at_baseline(outputs(state_dir))

    # A learner-like client: M1 alone above baseline flexes the hip (Fig 1d), ticks at about 78 Hz.
    n = 156
    handle = peer.play(np.tile([BASELINE, 0.8, BASELINE], (n, 1)))
    assert handle.accepted
    response = peer.wait(handle.get_result_async(), 30.0)
    assert response.status == GoalStatus.STATUS_SUCCEEDED, response.result.message
    rec = recording_from_msg(response.result.samples)
    assert len(rec) == n
    assert rec.position_rad[-1, 0] - rec.position_rad[0, 0] > math.radians(15)
    # Paced by the hardware loop's deadlines: no faster than 78 Hz. (A loaded machine makes it slower, which
    # is speed, not behaviour: benchmarks/bench_driver.py measures the rate.)
    assert np.median(np.diff(rec.t_s)) * 78.0 > 0.9
    assert np.all(rec.energy_j[-1] > rec.energy_j[0])

    # Bad commands never reach the PWM: the outputs stay at baseline.
    for bad in ([math.nan, 0.9, 0.9], [0.9, 0.9], [math.inf, 0.5, 0.5]):
        peer.cmd.publish(MotorActivation(activation=bad))
    with peer.lock:
        before = len(peer.applied)
    wait_until(lambda: len(peer.applied) > before + 20, 10.0, "more ticks")
    with peer.lock:
        assert all(a == [BASELINE] * 3 for a in peer.applied[before:])
    assert at_baseline(outputs(state_dir))

    peer.wait_for_servers({"reset": peer.reset.service_is_ready}, 30.0)  # served from activation on
    response = peer.wait(peer.reset.call_async(Trigger.Request()), 60.0)
    assert response.success, response.message

    wait_until(lambda: peer.hardware_status() is not None, 10.0, "hardware diagnostics")
    status = peer.hardware_status()
    assert status is not None and status["active"] == "1" and status["hardware_faults"] == "0"
    assert 0.0 < float(status["current_sample_rate_hz"]) <= 500.0 * 1.01  # sampling, never in bursts

    assert peer.transition(Transition.TRANSITION_DEACTIVATE), driver.log()
    assert peer.state() == State.PRIMARY_STATE_INACTIVE
    assert at_baseline(outputs(state_dir))  # inactive: tendons held at baseline tension

    assert peer.transition(Transition.TRANSITION_CLEANUP), driver.log()
    assert is_off(outputs(state_dir))
    assert outputs(state_dir)["closed"] is True
    assert peer.transition(Transition.TRANSITION_UNCONFIGURED_SHUTDOWN)
    assert peer.state() == State.PRIMARY_STATE_FINALIZED


def test_persistent_fault_drives_the_node_to_error_processing_with_outputs_off(
    driver: NodeProcess, peer: LifecyclePeer, state_dir: Path
) -> None:
    peer.wait_for_driver()
    assert peer.transition(Transition.TRANSITION_CONFIGURE), driver.log()
    assert peer.transition(Transition.TRANSITION_ACTIVATE), driver.log()
    handle = peer.play(np.tile([0.6, 0.15, 0.6], (20 * 78, 1)))
    assert handle.accepted
    wait_until(lambda: peer.count_applied([0.6, 0.15, 0.6]) > 30, 10.0, "the sequence to play")
    # The distal encoder's frames fail their parity check from now on.
    (state_dir / "faults.json").write_text(
        json.dumps([{"kind": "encoder_parity", "target": "distal", "count": -1}])
    )
    response = peer.wait(handle.get_result_async(), 30.0)
    assert response.status == GoalStatus.STATUS_ABORTED
    assert "plant fault" in response.result.message
    wait_until(
        lambda: State.PRIMARY_STATE_UNCONFIGURED in peer.goal_states()[-1:],
        10.0,
        "the end of error processing",
    )
    assert State.TRANSITION_STATE_ERRORPROCESSING in peer.goal_states()
    assert peer.state() == State.PRIMARY_STATE_UNCONFIGURED
    assert is_off(outputs(state_dir))
    assert "consecutive faulted ticks" in driver.log()

    # The fault persists: configuring again fails and names the device; once fixed, it succeeds.
    assert not peer.transition(Transition.TRANSITION_CONFIGURE)
    assert "distal encoder" in driver.log()
    (state_dir / "faults.json").write_text("[]")
    assert peer.transition(Transition.TRANSITION_CONFIGURE), driver.log()
    assert is_off(outputs(state_dir))


def test_deactivate_during_a_sequence_aborts_it_and_activating_again_serves_again(
    driver: NodeProcess, peer: LifecyclePeer, state_dir: Path
) -> None:
    peer.wait_for_driver()
    assert peer.transition(Transition.TRANSITION_CONFIGURE), driver.log()
    assert peer.transition(Transition.TRANSITION_ACTIVATE), driver.log()
    handle = peer.play(np.tile([0.15, 0.9, 0.15], (20 * 78, 1)))
    wait_until(lambda: peer.count_applied([0.15, 0.9, 0.15]) > 30, 10.0, "the sequence to play")
    assert peer.transition(Transition.TRANSITION_DEACTIVATE), driver.log()
    assert peer.wait(handle.get_result_async(), 30.0).status == GoalStatus.STATUS_ABORTED
    assert at_baseline(outputs(state_dir))

    assert peer.transition(Transition.TRANSITION_ACTIVATE), driver.log()
    response = peer.wait(peer.play(np.full((20, 3), 0.3)).get_result_async(), 30.0)
    assert response.status == GoalStatus.STATUS_SUCCEEDED
    assert len(recording_from_msg(response.result.samples)) == 20


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_signals_while_playing_leave_the_outputs_off(
    tmp_path: Path, state_dir: Path, peer: LifecyclePeer, sig: int
) -> None:
    proc = start_driver(tmp_path, state_dir, "autostart:=true")
    try:
        handle = peer.play(np.tile([0.9, 0.9, 0.9], (20 * 78, 1)))
        assert handle.accepted
        # Count the sequence's own ticks: the driver publishes baseline ticks before the goal starts too.
        wait_until(lambda: peer.count_applied([0.9, 0.9, 0.9]) > 30, 30.0, "the sequence to play")
        assert outputs(state_dir)["activation"][0] > 0.8
    finally:
        code = proc.stop(sig)
    assert code == 0, proc.log_path.read_text()
    out = outputs(state_dir)
    assert is_off(out) and out["closed"] is True


def test_invalid_rig_description_fails_configure_and_names_the_field(
    tmp_path: Path, state_dir: Path, peer: LifecyclePeer
) -> None:
    bad = tmp_path / "wiring.yaml"
    bad.write_text("pwm:\n  frequency_hz: 5000.0\n")
    proc = start_driver(tmp_path, state_dir, f"wiring:={bad}")
    try:
        peer.wait_for_driver()
        assert not peer.transition(Transition.TRANSITION_CONFIGURE)
        assert peer.state() == State.PRIMARY_STATE_UNCONFIGURED
    finally:
        assert proc.stop() == 0, proc.log_path.read_text()
    assert "pwm.frequency_hz" in proc.log_path.read_text()


def test_tendon_check_passes_on_the_fake_rig(tmp_path: Path, state_dir: Path) -> None:
    driver = start_driver(tmp_path, state_dir, "autostart:=true")
    try:
        check = NodeProcess("g2p_driver", "tendon_check", [], tmp_path)
        try:
            code = check.popen.wait(180.0)
        finally:
            check.stop()
        text = check.log_path.read_text()
        assert code == 0, text + driver.log()
        assert "every tendon moves its joints as in Fig 1d" in text
    finally:
        assert driver.stop() == 0, driver.log_path.read_text()
    assert is_off(outputs(state_dir))


def play_at_full_activation(
    tmp_path: Path, state_dir: Path, peer: LifecyclePeer, ticks: int, *parameters: str
) -> Recording:
    """Every motor at activation 1 for `ticks` on a driver derating from 26 degC, and what it applied."""
    driver = start_driver(
        tmp_path,
        state_dir,
        "rig.envelope.derate_start_c:=26.0",
        "rig.envelope.derate_full_c:=30.0",
        *parameters,
    )
    try:
        peer.wait_for_driver()
        assert peer.transition(Transition.TRANSITION_CONFIGURE), driver.log()
        assert peer.transition(Transition.TRANSITION_ACTIVATE), driver.log()
        response = peer.wait(peer.play(np.ones((ticks, 3))).get_result_async(), 30.0)
        assert response.status == GoalStatus.STATUS_SUCCEEDED, response.result.message
        assert peer.transition(Transition.TRANSITION_DEACTIVATE), driver.log()
    finally:
        assert driver.stop() == 0, driver.log_path.read_text()
    return recording_from_msg(response.result.samples)


def test_the_drivers_envelope_takes_the_rigs_calibrated_winding(
    tmp_path: Path, state_dir: Path, peer: LifecyclePeer
) -> None:
    # A winding calibrated at 6 ohm heats the estimate 10 times as fast as the rated 0.6 ohm: from rest at
    # activation 1 (8 A) it passes 26 degC within about 15 ticks, the rated one after about 60. Ticks that
    # run late only heat the estimate sooner, so tick 25 is derated however the machine keeps time.
    calibration = tmp_path / "calib.yaml"
    calibration.write_text(
        "format: g2p-leg-calibration\nversion: 1\nmodel: g2p_leg\nparameters: {motor_resistance_ohm: 6.0}\n"
    )
    rec = play_at_full_activation(tmp_path, state_dir, peer, 60, f"rig.envelope.calibration:={calibration}")
    assert np.all(rec.activation[25] < 1.0)


@pytest.mark.parametrize(("fake_devices", "heavy"), [(False, set()), (True, {"mujoco"})])
def test_the_driver_imports_mujoco_only_for_fake_devices_and_never_torch(
    fake_devices: bool, heavy: set[str]
) -> None:
    """The Pi runs the driver with neither torch nor MuJoCo installed: the node must not import them."""
    code = (
        "import sys, rclpy\n"
        "from g2p_driver.driver import DriverNode\n"
        f"rclpy.init(args=['x', '--ros-args', '-p', 'fake_devices:={str(fake_devices).lower()}'])\n"
        "node = DriverNode()\n"
        "print(sorted({'torch', 'mujoco'} & set(sys.modules)))\n"
        "node.destroy_node(); rclpy.shutdown()\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == str(sorted(heavy))


def test_the_driver_derates_a_hot_motor_from_its_measured_currents(
    tmp_path: Path, state_dir: Path, peer: LifecyclePeer
) -> None:
    # Derating from 26 degC: a few seconds at activation 1 heat the windings' estimate that far, from the
    # fake INA219s' currents.
    rec = play_at_full_activation(tmp_path, state_dir, peer, 390)
    assert np.all(rec.activation[12:16] == 1.0)  # cold: untouched, once the ramp climbed from rest
    assert np.all(rec.activation[-1] < 1.0)  # hot: derated toward baseline
    assert np.all(rec.current_a[-1] < rec.current_a[len(rec) // 4])
