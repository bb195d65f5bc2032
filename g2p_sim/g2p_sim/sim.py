"""`ros2 run g2p_sim sim`: the MuJoCo leg on a treadmill, serving the rig contract like the hardware."""

from __future__ import annotations

import enum
import sys
from dataclasses import dataclass

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

from g2p.rig import DEFAULT_NAMESPACE
from g2p.rig.tick_loop import Pacing
from g2p.sim import MujocoLeg, MujocoLegConfig
from g2p.sim.model import ModelError
from g2p.sim.model_description import leg_description
from g2p.validation import ConfigError
from g2p_ros.params import config_as_dict, declare_config, publish_config, report_invalid_parameter
from g2p_ros.rig_server import RigServer, RigServerConfig
from g2p_ros.robot_description import publish_robot_description
from g2p_ros.signals import init_with_stop_event, spin_until_stopped
from g2p_ros.spinner import MultiThreadedExecutor


class TimeMode(enum.Enum):
    """How simulated time relates to wall time."""

    REALTIME = "realtime"
    FAST = "fast"


@dataclass(frozen=True)
class SimConfig:
    """The simulator node's own settings.

    Attributes:
        time_mode: "realtime": ticks paced by the wall clock, stamps in system time, like the hardware.
            "fast": ticks only while there is work (a run_activations sequence, or one tick per
            activation_cmd), as fast as the graph consumes them; stamps and /clock in simulation time
            from 0, so every other node runs with use_sim_time.
    """

    time_mode: TimeMode = TimeMode.REALTIME


class SimNode(Node):
    """Builds the MuJoCo plant from parameters and serves the rig contract for it."""

    def __init__(self) -> None:
        super().__init__("sim", namespace=DEFAULT_NAMESPACE)
        self.config = declare_config(self, SimConfig)
        leg_config = declare_config(self, MujocoLegConfig, "leg.")
        server_config = declare_config(self, RigServerConfig, "rig.")
        fast = self.config.time_mode is TimeMode.FAST
        leg = MujocoLeg(leg_config)
        self.rig = RigServer(
            self,
            leg,
            Pacing.ON_DEMAND if fast else Pacing.WALL_CLOCK,
            server_config,
            sim_time=fast,
            publish_clock=True,
        )
        self._config_pub = publish_config(
            self,
            {
                **config_as_dict(self.config),
                "leg": config_as_dict(leg_config),
                # The values themselves, so the bag says which calibration ran wherever its file is.
                "calibration": leg.calibration.as_dict(),
                "rig": config_as_dict(server_config),
            },
        )
        # The URDF of the very model it runs, so a raised carriage or a custom model draws as it runs.
        try:
            self._description_pub = publish_robot_description(self, leg_description(leg.model))
        except ModelError as err:  # a custom model without the drawn elements still simulates
            self.get_logger().warning(f"no robot_description: {err}")
        self.rig.start()
        self.get_logger().info(
            f"MuJoCo leg serving the rig contract in {self.get_namespace()} "
            f"({self.config.time_mode.value} time)"
        )

    def destroy_node(self) -> None:
        """Stop serving the rig contract, then destroy the node."""
        if hasattr(self, "rig"):  # not when construction failed: rclpy's shutdown destroys such nodes too
            self.rig.destroy()
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    """Entry point of `ros2 run g2p_sim sim`."""
    stop = init_with_stop_event(args)  # the context stays valid until the rig has stopped and flushed
    node = None
    executor = MultiThreadedExecutor(num_threads=3)
    try:
        node = SimNode()
        executor.add_node(node)
        spin_until_stopped(executor, stop)
    except ConfigError as err:  # a bad leg.calibration file included
        sys.exit(report_invalid_parameter("g2p_sim", err))
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.rig.stop()  # goals end, the final baseline tick goes out and is acknowledged
            executor.shutdown()  # once its callbacks have returned: none uses a destroyed entity
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
