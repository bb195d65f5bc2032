"""`ros2 run g2p_bringup bringup`: start the graph described in config/graph.yaml, one process per node.

All nodes start at once; the learner starts its run only once the rig serves it and the recorder has
subscribed to the rig's topics (its `recorder_node` parameter), so nothing goes unrecorded. When the main
node (the learner) exits, or on Ctrl-C / SIGTERM, the processes are stopped in an order that loses nothing:
learner first (it cancels its goal, the rig drops to baseline), then the rig, then the recorder, which
finalizes the bag. Then the run's report is written beside the bag.

On two hosts, each host starts its own part (docs/DEPLOYMENT.md): the rig host the rig and the recorder,
serving until Ctrl-C; the workstation the learner, which waits for the rig and the recorder. DDS then
runs over UDP on the named interface only.

    ros2 run g2p_bringup bringup [--rig sim|sim_realtime|sim_air] [--set learner.search.threshold_mm=64.0] ...
    ros2 run g2p_bringup bringup --view --rig sim_realtime      # watch it in Foxglove as it happens
    ros2 run g2p_bringup bringup --host rig --dds-interface eth0 --rig hardware
    ros2 run g2p_bringup bringup --host workstation --dds-interface wlan0
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import IO, Any

import numpy as np
import rclpy
import yaml
from ament_index_python.packages import PackageNotFoundError, get_package_prefix, get_package_share_directory
from rclpy.utilities import remove_ros_args

from g2p.bags.runs import new_run_id
from g2p_bringup.dds import (
    clean_shared_memory,
    interface_address,
    one_host_environment,
    two_host_environment,
)
from g2p_bringup.graph import HOSTS, Graph, GraphError, NodeSpec, load_graph
from g2p_ros.params import RCLPY_PARAMETERS
from g2p_ros.signals import init_with_stop_event

STOP_TIMEOUT_S = 20.0


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="bringup", description=__doc__.splitlines()[0])
    parser.add_argument(
        "--graph",
        type=Path,
        default=None,
        help="graph description (default: the installed g2p_bringup config/graph.yaml)",
    )
    parser.add_argument(
        "--rig", default=None, help="which rig of the description to start (default: the first)"
    )
    parser.add_argument("--bags-dir", default="bags", help="directory of recorded runs (default: bags)")
    parser.add_argument("--run-id", default="", help="id of the run (default: UTC time and a random suffix)")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NODE.PARAM=VALUE",
        help="override a node's parameter (one it has: a misspelt name is refused); VALUE is YAML (write "
        "floats as 1.0)",
    )
    parser.add_argument("--no-report", action="store_true", help="do not write the run's report")
    parser.add_argument(
        "--view",
        action="store_true",
        help="also start the live viewer: open ws://127.0.0.1:8765 in Foxglove (docs/VIEWER.md)",
    )
    parser.add_argument(
        "--host",
        choices=HOSTS,
        default=None,
        help="start only this host's part of a two-host graph (default: the whole graph on this host)",
    )
    parser.add_argument(
        "--dds-interface",
        default="",
        metavar="NAME",
        help="with --host: the network interface DDS may use (e.g. eth0); no other one carries traffic",
    )
    options = parser.parse_args(remove_ros_args(argv)[1:])
    if options.host and not options.dds_interface:
        parser.error("--host needs --dds-interface: name the interface that joins the two hosts")
    return options


def _overrides(settings: list[str]) -> dict[str, dict[str, Any]]:
    out: dict[str, dict[str, Any]] = {}
    for item in settings:
        key, sep, value = item.partition("=")
        node, dot, param = key.partition(".")
        if not sep or not dot or not param:
            raise GraphError(f"--set {item!r}: expected NODE.PARAM=VALUE")
        out.setdefault(node, {})[param] = yaml.safe_load(value)
    return out


def node_parameters(spec: NodeSpec) -> frozenset[str] | None:
    """Every parameter the node's executable declares, without starting it; None for another project's.

    This project's executable `<package> <executable>` is the module `<package>.<executable>`, whose
    `node_parameters()` lists its node's parameters (g2p_ros.params.parameter_names: the names
    declare_config gives its configuration's fields). Imported only for a node that has overrides.
    """
    module = f"{spec.package}.{spec.executable}"
    try:
        found = importlib.util.find_spec(module)
    except ModuleNotFoundError:  # no such package
        found = None
    listing = getattr(importlib.import_module(module), "node_parameters", None) if found else None
    return None if listing is None else frozenset([*listing(), *RCLPY_PARAMETERS])


def _node_environment(profile_dir: Path, dds_interface: str = "") -> dict[str, str]:
    """The nodes' environment: ours, with the graph's Fast DDS profile unless one is set already.

    The profile is written into `profile_dir`; on two hosts, the UDP-only one for `dds_interface`.
    """
    env = dict(os.environ)
    if dds_interface:
        return two_host_environment(env, interface_address(dds_interface), profile_dir)
    env.update(one_host_environment(env, profile_dir))
    return env


class Process:
    """One node of the graph running as a child process in its own session (Ctrl-C reaches only us)."""

    def __init__(self, spec: NodeSpec, params_dir: Path, log_dir: Path, env: dict[str, str]) -> None:
        self.spec = spec
        params_file = params_dir / f"{spec.name}.yaml"
        params_file.write_text(spec.parameters_yaml())
        executable = Path(get_package_prefix(spec.package)) / "lib" / spec.package / spec.executable
        command = [str(executable), *spec.arguments, *spec.ros_arguments(params_file)]
        self.log_path = log_dir / f"{spec.name}.log"
        self._log: IO[bytes] | None = None
        if spec.main:
            out = None  # the main node talks to the user
        else:
            self._log = open(self.log_path, "wb")
            out = self._log
        self.popen = subprocess.Popen(
            command,
            stdout=out,
            stderr=subprocess.STDOUT if out else None,
            start_new_session=True,
            env=env,
        )

    def running(self) -> bool:
        """Whether the process is still running."""
        return self.popen.poll() is None

    def stop(self, timeout_s: float = STOP_TIMEOUT_S) -> int:
        """SIGINT, then SIGTERM, then SIGKILL, each after `timeout_s`; returns the exit code."""
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            if not self.running():
                break
            self.popen.send_signal(sig)
            try:
                self.popen.wait(timeout_s)
            except subprocess.TimeoutExpired:
                print(f"bringup: {self.spec.name} did not stop on {sig.name}", file=sys.stderr)
        if self._log is not None:
            self._log.close()
        return self.popen.wait()


def run(graph: Graph, log_dir: Path, stop: threading.Event, dds_interface: str = "") -> int:
    """Start the graph, wait for the main node to exit (or for `stop`), stop everything; main's exit code.

    The nodes start together; the learner waits for the rig and the recorder itself (its `recorder_node`
    parameter). When another node exits first, the run is stopped: nothing runs unrecorded or unattended.
    A graph without a main node (the rig host's part) runs until `stop`; its exit code is then 0.
    """
    procs: list[Process] = []
    code = 1
    clean_shared_memory()  # what killed processes left in /dev/shm
    with tempfile.TemporaryDirectory(prefix="g2p-bringup-") as params_dir:
        try:
            env = _node_environment(Path(params_dir), dds_interface)
            procs = [Process(spec, Path(params_dir), log_dir, env) for spec in graph.nodes]
            main = next((p for p in procs if p.spec is graph.main), None)
            while (main is None or main.running()) and not stop.is_set():
                ended = [p for p in procs if p is not main and not p.running()]
                if ended:
                    print(
                        f"bringup: {ended[0].spec.name} exited (code {ended[0].popen.returncode}); "
                        f"stopping the run; see {ended[0].log_path}",
                        file=sys.stderr,
                    )
                    if main is not None:
                        main.stop()
                    return 1
                time.sleep(0.1)
            # On stop: SIGINT lets the learner cancel its goal (rig to baseline).
            code = main.stop() if main is not None else 0
        finally:
            # Rig before recorder, so the recorder sees everything the rig published.
            for proc in procs:
                proc.stop()
    return code


def main(args: list[str] | None = None) -> None:
    """Entry point of `ros2 run g2p_bringup bringup`."""
    argv = sys.argv if args is None else args
    options = _parse(argv)
    stop = init_with_stop_event(argv)
    code = 1
    try:
        run_id = options.run_id or new_run_id(datetime.now(timezone.utc), np.random.default_rng())
        graph_path = (
            options.graph or Path(get_package_share_directory("g2p_bringup")) / "config" / "graph.yaml"
        )
        graph = load_graph(
            graph_path,
            options.rig,
            {"run_id": run_id, "bags_dir": options.bags_dir},
            _overrides(options.set),
            options.host,
            frozenset({"viewer"}) if options.view else frozenset(),
            node_parameters,  # a misspelt --set is refused before any node starts
        )
        log_dir = Path("log") / "runs" / run_id
        log_dir.mkdir(parents=True, exist_ok=True)
        where = f" on the {options.host} host over {options.dds_interface}" if options.host else ""
        print(
            f"bringup: run {run_id}: {', '.join(n.name for n in graph.nodes)} in {graph.namespace}{where} "
            f"(logs in {log_dir})",
            flush=True,
        )
        if options.host == "rig":
            print(
                "bringup: serving the rig until Ctrl-C; start the learner with "
                "`bringup --host workstation --dds-interface <its interface>` on the workstation",
                flush=True,
            )
        code = run(graph, log_dir, stop, options.dds_interface)
        bag = Path(options.bags_dir) / run_id
        if not options.no_report and (bag / "metadata.yaml").exists():
            subprocess.run([sys.executable, "-m", "g2p.bags.report", str(bag)], check=False)  # g2p-report
    except (GraphError, PackageNotFoundError, ValueError) as err:
        print(f"bringup: {err}", file=sys.stderr)
        code = 2
    finally:
        rclpy.try_shutdown()
    sys.exit(code)  # a stop (Ctrl-C, SIGTERM) is a clean end: the learner then exits 0


if __name__ == "__main__":
    main()
