"""`ros2 run g2p_sim sim`: the MuJoCo leg on a treadmill, serving the rig contract like the hardware."""

from __future__ import annotations

import enum
import sys
from dataclasses import dataclass

from rclpy.node import Node

from g2p.rig import DEFAULT_NAMESPACE
from g2p.rig.tick_loop import Pacing
from g2p.sim import MujocoLeg, MujocoLegConfig
from g2p.sim.model import ModelError
from g2p.sim.model_description import leg_description
from g2p.validation import ConfigError
from g2p_ros.executable import run_node
from g2p_ros.params import (
    config_as_dict,
    declare_config,
    parameter_names,
    publish_config,
    refuse_undeclared_overrides,
)
from g2p_ros.rig_server import RigServer, RigServerConfig
from g2p_ros.robot_description import publish_robot_description
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
        refuse_undeclared_overrides(self)  # before the rig ticks: a refused simulator publishes nothing
        fast = self.config.time_mode is TimeMode.FAST
        try:
            leg = MujocoLeg(leg_config)
        except ModelError as err:  # the message names the file and what it lacks
            raise ConfigError(f"leg.model_path: {err}") from err
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


def node_parameters() -> list[str]:
    """The parameters SimNode declares besides rclpy's (bringup checks its `--set` overrides against them)."""
    return [
        *parameter_names(SimConfig),
        *parameter_names(MujocoLegConfig, "leg."),
        *parameter_names(RigServerConfig, "rig."),
    ]


def main(args: list[str] | None = None) -> None:
    """Entry point of `ros2 run g2p_sim sim`.

    Exit status 2: an invalid parameter, a bad leg.calibration or leg.model_path file included.
    """
    sys.exit(
        run_node(
            "g2p_sim",
            SimNode,
            args,
            executor=lambda: MultiThreadedExecutor(num_threads=3),
            # Goals end, the final baseline tick goes out and is acknowledged, while the context is valid.
            stop_node=lambda node: node.rig.stop(),
        )
    )


if __name__ == "__main__":
    main()
