"""`ros2 run g2p_driver tendon_check`: pull each tendon alone on the active rig and check Fig 1d.

The rig (the driver, active; or the simulator) must be serving the rig contract in /leg. Each tendon is
pulled alone at a low activation from rest (run_activations, after a reset) and the joint rotations are
compared with Fig 1d; the report names what a failure points at (a reversed encoder, swapped motor
channels). Exit code 0 when every tendon is right, 1 when not, 2 when the rig could not be driven.
Parameters: levels, hold_s, threshold_deg (g2p.rig.tendon_check.TendonCheckConfig).
"""

from __future__ import annotations

import sys

import rclpy
from rclpy.node import Node

from g2p.rig import DEFAULT_NAMESPACE, RigError
from g2p.rig.tendon_check import TendonCheckConfig, check_tendons
from g2p.validation import ConfigError
from g2p_ros.params import declare_config, refuse_undeclared_overrides, report_invalid_parameter
from g2p_ros.rig_client import RigClient
from g2p_ros.spinner import BackgroundSpinner, MultiThreadedExecutor


def main(args: list[str] | None = None) -> None:
    """Entry point of `ros2 run g2p_driver tendon_check`."""
    rclpy.init(args=args)
    node = Node("tendon_check", namespace=DEFAULT_NAMESPACE)
    executor = MultiThreadedExecutor(num_threads=2)
    executor.add_node(node)
    # Spun once the client exists: rclpy's ActionClient joins the node half-built (ros2/rclpy#1589).
    spinner = BackgroundSpinner(executor)
    client: RigClient | None = None
    code = 2
    try:
        config = declare_config(node, TendonCheckConfig)
        refuse_undeclared_overrides(node)
        client = RigClient(node, server_timeout_s=30.0)
        spinner.start()
        report = check_tendons(client, config)
        print(report.text())
        code = 0 if report.ok else 1
    except ConfigError as err:
        code = report_invalid_parameter("tendon_check", err)
    except RigError as err:
        print(f"tendon_check: {err}", file=sys.stderr)
    except KeyboardInterrupt:
        print("tendon_check: interrupted", file=sys.stderr)
    finally:
        if client is not None:
            client.destroy()
        spinner.stop()
        node.destroy_node()
        rclpy.try_shutdown()
    sys.exit(code)


if __name__ == "__main__":
    main()
