"""The `main()` of every node executable: start rclpy, build the node, spin it until SIGINT or SIGTERM, stop.

    def main(args: list[str] | None = None) -> None:
        sys.exit(run_node("g2p_sim", SimNode, args, stop_node=lambda node: node.rig.stop()))

The node stops in an order that loses nothing: its own stop (goals ended, outputs safe) while the context is
still valid, then the executor (once its callbacks have returned), then the node, then rclpy.
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable, Mapping
from typing import TypeVar

import rclpy
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node

from g2p.validation import ConfigError
from g2p_ros.params import refuse_undeclared_overrides, report_invalid_parameter
from g2p_ros.signals import init_with_stop_event, spin_until_stopped

NodeT = TypeVar("NodeT", bound=Node)


def spin(node: Node, executor: Executor, stop: threading.Event) -> int:
    """`run_node`'s default `run`: spin until SIGINT or SIGTERM (or the context shuts down); exit status 0."""
    spin_until_stopped(executor, stop)
    return 0


def run_node(
    program: str,
    make_node: Callable[[], NodeT],
    args: list[str] | None = None,
    *,
    executor: Callable[[], Executor] = SingleThreadedExecutor,
    run: Callable[[NodeT, Executor, threading.Event], int] = spin,
    stop_node: Callable[[NodeT], None] | None = None,
    errors: Mapping[type[Exception], tuple[str, int]] | None = None,
) -> int:
    """Run one node in its executable until it is stopped; returns the executable's exit status.

    SIGINT and SIGTERM only set the event `run` watches (`init_with_stop_event`). A parameter the node
    cannot use (`ConfigError`, an override naming no parameter it declared included) prints
    `<program>: invalid parameter ...` and ends with status 2.

    Args:
        program: the name error messages start with (e.g. "g2p_sim").
        make_node: builds the node, declaring all its parameters.
        args: command-line arguments for rclpy (None: sys.argv).
        executor: builds the executor, once rclpy is started.
        run: what the executable does with its node, added to the executor (by default spin until stopped);
            returns the exit status.
        stop_node: the node's own stop, before the executor shuts down (goals ended, outputs made safe).
        errors: other errors that end the executable: type -> (what, exit status), printed as
            `<program>: <what>: <error>`.
    """
    failures = dict(errors or {})
    stop = init_with_stop_event(args)  # the context stays valid until the node has stopped
    spinning = executor()
    node: NodeT | None = None
    code = 0
    try:
        node = make_node()
        refuse_undeclared_overrides(node)
        spinning.add_node(node)
        code = run(node, spinning, stop)
    except ConfigError as err:
        code = report_invalid_parameter(program, err)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except tuple(failures) as err:
        what, code = next(failure for kind, failure in failures.items() if isinstance(err, kind))
        print(f"{program}: {what}: {err}", file=sys.stderr)
    finally:
        if node is not None:
            if stop_node is not None:
                stop_node(node)
            spinning.shutdown()  # once its callbacks have returned: none uses a destroyed entity
            node.destroy_node()
        rclpy.try_shutdown()
    return code
