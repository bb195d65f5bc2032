"""Speed of the ROS graph in fast simulation, against the same work in-process.

    scripts/with-env python benchmarks/bench_graph.py [--ticks 23400] [--caps 60.0,0.0] [--repeats 3]
        [--skip-full-run]

1. Rig throughput: the installed `sim` in fast mode plays a babbling sequence through `run_activations`
   while one subscriber (another process) takes every message of every rig topic and /clock; reports
   simulated seconds per wall second, the messages received against those published, and the sim
   process's CPU time, for the default real-time-factor cap and without a cap.
2. The main job: the full G2P run through the graph (sim, recorder, learner as `bringup` starts them)
   against its simulated rig time, the learner's CPU time and peak memory, and the same run in-process
   (treadmill_in_process.py: run_treadmill on MujocoLeg, a Python process of its own) for the overhead ratios;
   medians of `--repeats` runs. Two ratios, each with the same boundaries on both sides:
   - process: from launching `bringup` to its exit, against launching the in-process script to its exit
     (both include the interpreter, imports, the run and the exit);
   - run: the learning run alone, from the learner's first babbling feedback to its summary line, against
     the `run_treadmill` call (torch imported beforehand).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import rclpy
from ament_index_python.packages import get_package_prefix
from rclpy.executors import MultiThreadedExecutor
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from g2p.bags.dataset import load_run
from g2p.learning.babbling import babbling_activations
from g2p_interfaces.action import RunActivations
from g2p_interfaces.msg import MotorActivation, MotorPower, Treadmill
from g2p_ros import contract
from g2p_ros.action_client import ActionClient

ROOT = Path(__file__).resolve().parents[1]


def installed(package: str, name: str) -> str:
    """The executable `ros2 run <package> <name>` runs."""
    return str(Path(get_package_prefix(package)) / "lib" / package / name)


def cpu_s(pid: int) -> float:
    """User + system CPU time of a running process (s)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def child_pid(parent: int, command_part: str) -> int | None:
    """The child process of `parent` whose command line contains `command_part`, if any."""
    children = Path(f"/proc/{parent}/task/{parent}/children")
    for pid in children.read_text().split() if children.exists() else []:
        try:
            if command_part in Path(f"/proc/{pid}/cmdline").read_text():
                return int(pid)
        except FileNotFoundError:
            continue
    return None


def peak_rss_mb(pid: int) -> float:
    """Peak resident memory of a running process (MB)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def subscriber_main(ticks: int) -> None:
    """Child process: count every message of every rig topic and /clock until `ticks` ticks arrived.

    Raw subscriptions on an EventsExecutor, like the recorder: rclpy's Python executors take fewer
    messages per second than the rig publishes, and a reader that falls 10,000 samples behind loses some.
    """
    rclpy.init()
    node = Node("bench_subscriber", namespace="/leg")
    counts = {"joint_states": 0, "treadmill": 0, "motor_power": 0, "applied_activation": 0, "clock": 0}
    deep = QoSProfile(depth=10000, reliability=ReliabilityPolicy.RELIABLE)

    def counter(name: str):
        def count(_msg: object) -> None:
            counts[name] += 1

        return count

    for name, msg_type in (
        ("joint_states", JointState),
        ("treadmill", Treadmill),
        ("motor_power", MotorPower),
        ("applied_activation", MotorActivation),
    ):
        node.create_subscription(msg_type, name, counter(name), deep, raw=True)
    node.create_subscription(Clock, "/clock", counter("clock"), contract.CLOCK_QOS, raw=True)
    executor = EventsExecutor()
    executor.add_node(node)
    print("ready", flush=True)
    deadline = time.monotonic() + 600
    while counts["applied_activation"] < ticks and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.5)
    end = time.monotonic() + 2.0
    while time.monotonic() < end:  # whatever is still in flight
        executor.spin_once(timeout_sec=0.1)
    print(json.dumps(counts), flush=True)
    node.destroy_node()
    rclpy.shutdown()


def rig_throughput(ticks: int, cap: float, clock_period_ticks: int) -> dict[str, float]:
    """Play `ticks` babbling ticks on the fast sim with one subscriber taking everything."""
    sim = subprocess.Popen(
        [
            installed("g2p_sim", "sim"),
            "--ros-args",
            "-p",
            "time_mode:=fast",
            "-p",
            f"rig.fast_max_real_time_factor:={cap}",
            "-p",
            f"rig.clock_period_ticks:={clock_period_ticks}",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    sub = subprocess.Popen(
        [sys.executable, __file__, "--subscriber", str(ticks)], stdout=subprocess.PIPE, text=True
    )
    assert sub.stdout is not None
    sub.stdout.readline()  # "ready"
    rclpy.init()
    node = Node("bench_client", namespace="/leg")
    executor = MultiThreadedExecutor()
    executor.add_node(node)
    client = ActionClient(node, RunActivations, contract.RUN_ACTIVATIONS)
    threading.Thread(target=executor.spin, daemon=True).start()  # after the client exists
    watch = contract.ServerWatch("run_activations", client.server_is_ready)
    assert watch.wait_until_ready(60.0)
    time.sleep(2.0)  # let the subscriber match the rig's publishers
    activations = babbling_activations(np.random.default_rng(0), n_samples=ticks)
    cpu0, t0 = cpu_s(sim.pid), time.perf_counter()
    goal = client.send_goal_async(RunActivations.Goal(activation=activations.ravel()))
    while not goal.done():
        time.sleep(0.01)
    result = goal.result().get_result_async()
    while not result.done():
        time.sleep(0.01)
    wall, cpu = time.perf_counter() - t0, cpu_s(sim.pid) - cpu0
    samples = result.result().result.samples
    sim_s = (samples.stamp_ns[-1] - samples.stamp_ns[0]) * 1e-9
    counts = json.loads(sub.communicate(timeout=120)[0].strip().splitlines()[-1])
    client.destroy()
    executor.shutdown()
    node.destroy_node()
    rclpy.shutdown()
    sim.send_signal(2)
    sim.wait(20)
    return {
        "cap": cap,
        "clock_period_ticks": clock_period_ticks,
        "ticks": ticks,
        "sim_s": sim_s,
        "wall_s": wall,
        "real_time_factor": sim_s / wall,
        "sim_cpu_s": cpu,
        "received": counts,
        "published_per_topic": ticks,
    }


def graph_run() -> dict[str, float]:
    """The main job through the graph: wall times, rig time, the learner's CPU time and peak memory."""
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        bringup = subprocess.Popen(
            [installed("g2p_bringup", "bringup"), "--bags-dir", tmp, "--run-id", "bench", "--no-report"],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
        )
        lines: list[tuple[float, str]] = []  # (s since launch, line) of the learner's progress output

        def read() -> None:
            assert bringup.stdout is not None
            for line in bringup.stdout:
                lines.append((time.perf_counter() - t0, line))

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        learner_pid, learner_cpu, learner_rss = None, 0.0, 0.0
        while bringup.poll() is None:
            if learner_pid is None:
                learner_pid = child_pid(bringup.pid, "g2p_learner/learn")
            if learner_pid is not None:
                try:
                    learner_cpu, learner_rss = cpu_s(learner_pid), max(learner_rss, peak_rss_mb(learner_pid))
                except (FileNotFoundError, ProcessLookupError):
                    pass
            time.sleep(0.2)
        wall = time.perf_counter() - t0
        reader.join(5.0)
        t_s = load_run(Path(tmp) / "bench").ticks.recording.t_s
    start = next(t for t, line in lines if line.startswith("babbling"))
    babbled = next(t for t, line in lines if line.startswith("babbling 100%"))
    attempts = [t for t, line in lines if line.startswith("attempt")]
    end = next(t for t, line in lines if line.startswith("| run "))
    return {
        "wall_s": wall,
        "start_s": start,
        "run_s": end - start,
        "babbling_s": babbled - start,
        "fit_and_first_attempt_s": attempts[0] - babbled,
        "other_attempts_s": attempts[-1] - attempts[0],
        "stop_s": wall - end,
        "rig_time_s": float(t_s[-1] - t_s[0]),
        "learner_cpu_s": learner_cpu,
        "learner_peak_rss_mb": learner_rss,
    }


def in_process_run() -> dict[str, float]:
    """The same run in-process, in a Python process of its own: its wall time and the run's."""
    t0 = time.perf_counter()
    out = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "treadmill_in_process.py")],
        check=True,
        stdout=subprocess.PIPE,
        text=True,
    ).stdout
    return {"wall_s": time.perf_counter() - t0, **json.loads(out.strip().splitlines()[-1])}


def full_run(repeats: int) -> dict[str, object]:
    """The main job through the graph and in-process, `repeats` times each; medians and every run."""
    graph = [graph_run() for _ in range(repeats)]
    in_process = [in_process_run() for _ in range(repeats)]

    def median(runs: list[dict[str, float]], key: str) -> float:
        return float(np.median([r[key] for r in runs]))

    wall, rig_time = median(graph, "wall_s"), median(graph, "rig_time_s")
    return {
        "graph_wall_s": wall,
        "graph_start_s": median(graph, "start_s"),
        "graph_run_s": median(graph, "run_s"),
        "graph_babbling_s": median(graph, "babbling_s"),
        "graph_fit_and_first_attempt_s": median(graph, "fit_and_first_attempt_s"),
        "graph_other_attempts_s": median(graph, "other_attempts_s"),
        "graph_stop_s": median(graph, "stop_s"),
        "rig_time_s": rig_time,
        "real_time_factor": rig_time / wall,
        "in_process_wall_s": median(in_process, "wall_s"),
        "in_process_run_s": median(in_process, "run_s"),
        "overhead_process": wall / median(in_process, "wall_s"),
        "overhead_run": median(graph, "run_s") / median(in_process, "run_s"),
        "learner_cpu_s": median(graph, "learner_cpu_s"),
        "learner_peak_rss_mb": float(np.max([g["learner_peak_rss_mb"] for g in graph])),
        "graph_runs": graph,
        "in_process_runs": in_process,
    }


def main() -> None:
    """Run both measurements and print them as JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ticks", type=int, default=23400, help="ticks for the rig throughput (5 min)")
    parser.add_argument("--caps", default="60.0,0.0", help="real-time-factor caps to measure (0 = none)")
    parser.add_argument(
        "--clock-period-ticks", type=int, default=8, help="ticks per /clock message (graph.yaml's sim: 8)"
    )
    parser.add_argument("--repeats", type=int, default=3, help="full runs, each way (medians reported)")
    parser.add_argument("--skip-full-run", action="store_true")
    parser.add_argument("--subscriber", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.subscriber:
        subscriber_main(args.subscriber)
        return
    results: dict[str, object] = {
        "rig": [
            rig_throughput(args.ticks, float(cap), args.clock_period_ticks)
            for cap in args.caps.split(",")
            if cap
        ]
    }
    if not args.skip_full_run:
        results["full_run"] = full_run(args.repeats)
    print(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
