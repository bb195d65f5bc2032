"""`ros2 run g2p_driver driver`: the physical rig as a lifecycle node serving the rig contract.

Lifecycle (lifecycle_msgs services under /leg/driver/):
    configure   read the wiring (YAML), open and set up the devices; motor outputs stay off.
    activate    serve the rig contract (RigServer, paced by the hardware loop); the plant's reset switches
                the motor drivers on at baseline tension and waits for the leg to come to rest.
    deactivate  stop serving; outputs hold baseline tension.
    cleanup, shutdown, error
                outputs to baseline, then off; devices released.
A persistent hardware fault, an exception in the tick loop or a stalled loop drive the node through
deactivate into error processing (outputs baseline, then off), ending unconfigured. Ctrl-C and SIGTERM
stop the tick loop and leave the outputs off before the process exits. With `fake_devices:=true` the same
node runs on the physics-backed fake buses of `g2p.hardware_fake.buses` (no Raspberry Pi needed).

At construction, whatever the lifecycle state, the node publishes the leg's URDF, latched, on
`robot_description`: the file `description_file` (default the packaged g2p/description/models/leg.urdf),
or with fake devices the URDF of the MuJoCo model behind the fake buses.
"""

from __future__ import annotations

import logging
import sys
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import Executor
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from std_msgs.msg import Header

from g2p.description.urdf import UrdfError, leg_urdf, packaged_urdf_path, read_leg_urdf
from g2p.hardware import HardwareError, HardwareLeg, HardwareLegConfig, load_wiring, open_devices
from g2p.rig import DEFAULT_NAMESPACE
from g2p.rig.tick_loop import Pacing
from g2p.validation import ConfigError, require, require_positive
from g2p_ros import contract
from g2p_ros.executable import run_node
from g2p_ros.params import config_as_dict, declare_config, parameter_names, publish_config
from g2p_ros.rig_server import RigServer, RigServerConfig
from g2p_ros.robot_description import publish_robot_description
from g2p_ros.spinner import MultiThreadedExecutor

if TYPE_CHECKING:
    from g2p.hardware_fake.buses import FakeBuses, FakeBusesConfig

PACKAGE = "g2p_driver"
# How long activate waits for the spinning thread to destroy the stopped rig servers (s). It is woken at
# once and only finishes the spin_once it is in; this bounds the wait on an executor that no longer spins.
RETIRED_DESTROY_TIMEOUT_S = 5.0


@dataclass(frozen=True)
class DriverConfig:
    """The driver node's own settings (the plant's are under `leg.`, the contract's under `rig.`).

    Attributes:
        wiring: path of the rig's wiring description (YAML); "" uses the installed config/wiring.yaml.
        description_file: the leg's URDF, published as robot_description, as it is (it must describe the
            leg as g2p.description.urdf writes it); "" uses the packaged g2p/description/models/leg.urdf.
            Unused with fake_devices: the fake rig's MuJoCo model is described.
        fake_devices: run on the physics-backed fake buses (MuJoCo leg) instead of the Pi's devices;
            `fake.*` parameters set them up.
        autostart: configure and activate at start-up, for a graph without a lifecycle manager.
        diagnostics_period_s: wall time between two hardware status messages on /diagnostics (s).
        stall_fault_s: while active, a tick loop that ran no tick for this long is a fault (s).
    """

    wiring: str = ""
    description_file: str = ""
    fake_devices: bool = False
    autostart: bool = False
    diagnostics_period_s: float = 1.0
    stall_fault_s: float = 1.0

    def __post_init__(self) -> None:
        require_positive(self.diagnostics_period_s, "diagnostics_period_s")
        require_positive(self.stall_fault_s, "stall_fault_s")


def default_wiring_path() -> Path:
    """The installed example wiring description, share/g2p_driver/config/wiring.yaml."""
    try:
        return Path(get_package_share_directory(PACKAGE)) / "config" / "wiring.yaml"
    except PackageNotFoundError:
        return Path(__file__).resolve().parents[1] / "config" / "wiring.yaml"


class _RosLogHandler(logging.Handler):
    """Forwards the core library's log records (g2p.hardware) to the node's ROS logger."""

    def __init__(self, node: LifecycleNode) -> None:
        super().__init__()
        self._logger = node.get_logger()

    def emit(self, record: logging.LogRecord) -> None:
        text = self.format(record)
        if record.levelno >= logging.ERROR:
            self._logger.error(text)
        elif record.levelno >= logging.WARNING:
            self._logger.warning(text)
        else:
            self._logger.info(text)


class DriverNode(LifecycleNode):
    """Opens the rig's devices on configure and serves the rig contract while active."""

    def __init__(self) -> None:
        super().__init__("driver", namespace=DEFAULT_NAMESPACE)
        # What make_safe and destroy_node use, first: rclpy's shutdown destroys a node whose construction
        # failed (an invalid parameter) too.
        self.leg: HardwareLeg | None = None
        self.fake: FakeBuses | None = None
        self._server: RigServer | None = None
        # Stopped rig servers, destroyed later by the spinning thread (see _destroy_retired_safely).
        self._retired: list[RigServer] = []
        self._retired_changed = threading.Condition()
        self._retired_destroy_requested = False
        self._spinning_thread: int | None = None
        self._active = False
        self._log_handler = _RosLogHandler(self)
        self.config = declare_config(self, DriverConfig)
        self.leg_config = declare_config(self, HardwareLegConfig, "leg.")
        self.rig_server_config = declare_config(self, RigServerConfig, "rig.")
        # The fake rig and its MuJoCo leg are imported only when asked for: the Pi needs neither.
        self.fake_config: FakeBusesConfig | None = None
        if self.config.fake_devices:
            from g2p.hardware_fake.buses import FakeBusesConfig

            self.fake_config = declare_config(self, FakeBusesConfig, "fake.")
        require(
            self.leg_config.baseline_activation == self.rig_server_config.baseline_activation,
            "leg.baseline_activation",
            f"must equal rig.baseline_activation ({self.rig_server_config.baseline_activation}), "
            f"got {self.leg_config.baseline_activation}",
        )
        document = {**config_as_dict(self.config), "leg": config_as_dict(self.leg_config)}
        document["rig"] = config_as_dict(self.rig_server_config)
        if self.fake_config is not None:
            document["fake"] = config_as_dict(self.fake_config)
        self._config_pub = publish_config(self, document)
        self._description_pub = publish_robot_description(self, self._robot_description())
        logging.getLogger("g2p.hardware").addHandler(self._log_handler)
        self._fault: Exception | None = None
        self._fault_lock = threading.Lock()
        # The default callback group is mutually exclusive and holds the lifecycle services: a fault
        # reported by the loop thread is acted on here, never during another transition.
        self._fault_signal = self.create_guard_condition(self._on_fault_signal)
        # Only wakes the spinning thread (spin_once returns) to destroy the retired servers; its own group,
        # as the default one is busy with the transition that waits for it.
        self._spinner_signal = self.create_guard_condition(
            lambda: None, callback_group=ReentrantCallbackGroup()
        )
        self._pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", contract.DIAGNOSTICS_QOS)
        self._diag_timer = self.create_timer(self.config.diagnostics_period_s, self._publish_diagnostics)
        self._stall_timer = self.create_timer(0.1, self._check_stall)

    def _robot_description(self) -> str:
        """The URDF of the leg this node drives (robot_description).

        Raises:
            ConfigError: description_file cannot be read or does not describe the leg.
        """
        if self.fake_config is not None:
            from g2p.hardware_fake.buses import fake_leg_config
            from g2p.sim.model_description import config_description

            return leg_urdf(config_description(fake_leg_config(self.fake_config)))
        path = Path(self.config.description_file) if self.config.description_file else packaged_urdf_path()
        try:
            return read_leg_urdf(path)
        except (OSError, UrdfError) as err:
            raise ConfigError(f"description_file: {err}") from err

    # Lifecycle transitions ----------------------------------------------------------------------------

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Read the wiring description and open the devices (outputs off)."""
        path = Path(self.config.wiring) if self.config.wiring else default_wiring_path()
        try:
            wiring = load_wiring(path)
            if self.fake_config is not None:
                from g2p.hardware_fake.buses import fake_devices

                self.fake, devices = fake_devices(wiring, self.fake_config)
            else:
                devices = open_devices(wiring)
            try:
                self.leg = HardwareLeg(devices, wiring, self.leg_config)
            except BaseException:
                devices.close()
                raise
        except (ConfigError, HardwareError, OSError) as err:
            self.get_logger().error(f"configure failed: {type(err).__name__}: {err}")
            self.fake = None
            return TransitionCallbackReturn.FAILURE
        where = "fake buses (MuJoCo leg)" if self.fake is not None else "the rig's buses"
        self.get_logger().info(f"configured from {path} on {where}; motor outputs off")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Serve the rig contract; the plant switches the outputs on at baseline and settles."""
        leg = self.leg  # once: a stop (SIGINT, SIGTERM) may make the node safe from another thread
        if leg is None:
            self.get_logger().error("activate failed: the devices are closed")
            return TransitionCallbackReturn.FAILURE
        # The servers stopped earlier (their goals ended since) serve the same names: gone first.
        if not self._destroy_retired_safely(RETIRED_DESTROY_TIMEOUT_S):
            self.get_logger().error(
                "activate failed: the stopped rig server was not destroyed within "
                f"{RETIRED_DESTROY_TIMEOUT_S:g} s"
            )
            return TransitionCallbackReturn.FAILURE
        with self._fault_lock:
            self._fault = None
        server = RigServer(self, leg, Pacing.PLANT, self.rig_server_config, on_fault=self._on_loop_fault)
        try:
            server.start()
        except Exception as err:
            self.get_logger().error(f"activate failed: {type(err).__name__}: {err}")
            self._retire(server)
            return TransitionCallbackReturn.ERROR
        self._server = server
        self._active = True
        self.get_logger().info(
            f"active: serving the rig contract in {self.get_namespace()} at {leg.tick_hz:g} Hz"
        )
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop serving; outputs hold baseline. A pending fault turns this into error processing."""
        self._active = False
        self._stop_server()
        with self._fault_lock:
            fault, self._fault = self._fault, None
        if self.leg is not None and fault is None:
            try:
                self.leg.hold_baseline()
            except (OSError, HardwareError) as err:
                fault = err
        if fault is not None:
            self.get_logger().error(f"hardware fault: {type(fault).__name__}: {fault}")
            return TransitionCallbackReturn.ERROR
        self.get_logger().info("inactive: outputs at baseline")
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Outputs to baseline then off, devices released."""
        self.make_safe()
        self.get_logger().info("unconfigured: outputs off, devices released")
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Outputs to baseline then off, devices released."""
        self.make_safe()
        self.get_logger().info("finalized: outputs off, devices released")
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Outputs to baseline then off, devices released; the node ends unconfigured (reconfigurable)."""
        self.make_safe()
        self.get_logger().error("error processed: outputs off, devices released; configure to retry")
        return TransitionCallbackReturn.SUCCESS

    # Safety ---------------------------------------------------------------------------------------------

    def make_safe(self) -> None:
        """Stop the tick loop, then outputs to baseline and off, devices released; never raises."""
        self._active = False
        try:
            self._stop_server()
        except Exception as err:  # keep going: the outputs matter more than a clean stop
            self.get_logger().error(f"stopping the rig server: {type(err).__name__}: {err}")
        leg, self.leg = self.leg, None
        if leg is not None:
            try:
                leg.close()
            except Exception as err:
                self.get_logger().error(f"closing the hardware: {type(err).__name__}: {err}")
        self.fake = None

    def _stop_server(self) -> None:
        """Stop the tick loop; the server's entities are destroyed later (a goal may still be finishing)."""
        server, self._server = self._server, None
        if server is not None:
            server.stop()
            self._retire(server)

    def _retire(self, server: RigServer) -> None:
        with self._retired_changed:
            self._retired.append(server)

    def _destroy_retired_safely(self, timeout_s: float) -> bool:
        """Have the retired rig servers destroyed where rclpy allows it; True once none is left.

        rclpy's executor (9.1.2, ros2/rclpy#1385) lists a node's waitables (the action servers, the
        publishers' and subscription's event handlers), then enters each: one destroyed in between from
        another thread is added to the wait set all the same, and the spinning thread dies ("action
        server pointer is invalid"). So a callback never destroys them: it asks the spinning thread
        (`spin_until_stopped`), which does between two waits, and waits for it. With nothing spinning
        (before the spin) or from the spinning thread itself, they are destroyed here. False when the
        executor stopped spinning or `timeout_s` passed first.
        """
        with self._retired_changed:
            if not self._retired:
                return True
            spinning = self._spinning_thread
            if spinning is not None and spinning != threading.get_ident():
                self._retired_destroy_requested = True
        if spinning is None or spinning == threading.get_ident():
            self._destroy_retired()
            return True
        self._spinner_signal.trigger()
        with self._retired_changed:
            self._retired_changed.wait_for(
                lambda: not self._retired or self._spinning_thread is None, timeout_s
            )
            return not self._retired

    def spin_until_stopped(self, executor: Executor, stop: threading.Event) -> None:
        """Spin until `stop` (SIGINT, SIGTERM) or the context shuts down.

        Between two spin_once, the retired rig servers a transition asked to be destroyed are destroyed
        here (see `_destroy_retired_safely`).
        """
        with self._retired_changed:
            self._spinning_thread = threading.get_ident()
        try:
            while not stop.is_set() and executor.context.ok():
                executor.spin_once(timeout_sec=0.1)
                with self._retired_changed:
                    requested, self._retired_destroy_requested = self._retired_destroy_requested, False
                if requested:
                    self._destroy_retired()
        finally:
            with self._retired_changed:
                self._spinning_thread = None
                self._retired_changed.notify_all()  # a transition waiting for the spinning thread gives up

    def _destroy_retired(self) -> None:
        """Destroy the retired servers; only where no executor thread can be waiting on them."""
        with self._retired_changed:
            servers = list(self._retired)
        for server in servers:
            try:
                server.destroy()
            except Exception as err:
                self.get_logger().warning(f"destroying a stopped rig server: {type(err).__name__}: {err}")
        with self._retired_changed:
            self._retired = [s for s in self._retired if s not in servers]
            self._retired_changed.notify_all()

    def _on_loop_fault(self, err: Exception) -> None:
        """From the tick loop thread: record the fault, wake the executor (the plant is at baseline)."""
        with self._fault_lock:
            if self._fault is None:
                self._fault = err
        self._fault_signal.trigger()

    def _on_fault_signal(self) -> None:
        if self._active and self._fault is not None:
            self.get_logger().error("fault in the tick loop: going to error processing")
            self.trigger_deactivate()

    def _check_stall(self) -> None:
        leg = self.leg
        if not self._active or leg is None or not leg.running:
            return
        idle = leg.seconds_since_activity()
        if idle > self.config.stall_fault_s:
            self._on_loop_fault(RuntimeError(f"the tick loop ran no tick for {idle:.2f} s"))

    def _publish_diagnostics(self) -> None:
        leg = self.leg
        values: dict[str, float | int | str] = {"active": int(self._active)}
        level, message = DiagnosticStatus.OK, "ok"
        if leg is None:
            message = "unconfigured: outputs off"
        else:
            values.update(leg.diagnostics())
            c = leg.counters
            faults = (
                c.encoder_parity_errors + c.encoder_error_flags + c.spi_errors + c.i2c_errors + c.pwm_errors
            )
            if leg.fault is not None:
                level, message = DiagnosticStatus.ERROR, f"hardware fault: {leg.fault}"
            elif faults or c.watchdog_trips or c.late_ticks:
                level = DiagnosticStatus.WARN
                message = f"{faults} bus faults, {c.watchdog_trips} watchdog trips, {c.late_ticks} late ticks"
        status = DiagnosticStatus(
            level=level,
            name=f"{self.get_fully_qualified_name()}: hardware",
            hardware_id="g2p rig (fake buses)" if self.fake is not None else "g2p rig",
            message=message,
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()],
        )
        stamp = self.get_clock().now().to_msg()
        self._pub_diag.publish(DiagnosticArray(header=Header(stamp=stamp), status=[status]))

    def destroy_node(self) -> None:
        """Outputs safe, the rig servers destroyed, then the node.

        A failure once the outputs are safe is printed, not raised: the outputs matter more than tidy
        teardown, and the process keeps its exit status.
        """
        self.make_safe()
        try:
            self._destroy_retired()
            logging.getLogger("g2p.hardware").removeHandler(self._log_handler)
            super().destroy_node()
        except Exception as err:
            print(f"{PACKAGE}: destroying the node: {err}", file=sys.stderr)


def node_parameters() -> list[str]:
    """The parameters DriverNode declares besides rclpy's, `fake.*` included (declared with fake_devices).

    bringup checks its `--set` overrides against them.
    """
    names = [
        *parameter_names(DriverConfig),
        *parameter_names(HardwareLegConfig, "leg."),
        *parameter_names(RigServerConfig, "rig."),
    ]
    try:  # MuJoCo: imported only when asked for
        from g2p.hardware_fake.buses import FakeBusesConfig
    except ImportError:  # a Pi without MuJoCo has no fake devices
        return names
    return [*names, *parameter_names(FakeBusesConfig, "fake.")]


def _serve(node: DriverNode, executor: Executor, stop: threading.Event) -> int:
    """With `autostart`, configure and activate at once; then spin until SIGINT or SIGTERM."""
    if node.config.autostart and node.trigger_configure() == TransitionCallbackReturn.SUCCESS:
        node.trigger_activate()
    node.spin_until_stopped(executor, stop)
    return 0


def main(args: list[str] | None = None) -> None:
    """Entry point of `ros2 run g2p_driver driver`.

    SIGINT and SIGTERM are handled here rather than by rclpy: they end the spin loop, and the outputs are
    made safe (tick loop stopped, baseline, off) while the ROS context is still valid, so the loop and
    any running goal end cleanly before rclpy shuts down.
    """
    sys.exit(
        run_node(
            PACKAGE,
            DriverNode,
            args,
            executor=lambda: MultiThreadedExecutor(num_threads=4),
            run=_serve,
            # First, on its own: the outputs matter more than tidy teardown.
            stop_node=lambda node: node.make_safe(),
        )
    )


if __name__ == "__main__":
    main()
