"""Round trip of one TickPlant step (g2p_ros.tick_plant) against the installed `sim` in another process.

    scripts/with-env python benchmarks/bench_tick_plant.py [--steps 1000] [--realtime-steps 400]

Fast time: the policy's side publishes a command and waits for the tick it played (lockstep); reports
the wall time per step (median, 95th percentile, worst). Realtime: the rig ticks at 78 Hz on its own;
reports the same, and which command each tick returned applied: its step's, the previous step's (the
command arrived during the tick returned, whose activation the rig had already decided), the one before
that, or baseline (the watchdog). The commands are random and distinct, so each tick's applied activation
tells which command it played.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import numpy as np
import rclpy
from ament_index_python.packages import get_package_prefix
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from g2p.safety import BASELINE_ACTIVATION
from g2p_ros.spinner import BackgroundSpinner
from g2p_ros.tick_plant import TickPlant

# The envelope's soft limits and ramp change the applied activations: off, so that each tick's applied
# activation tells which command it played.
ENVELOPE_OFF = ("-p", "rig.envelope.soft_limits:=false", "-p", "rig.envelope.max_step:=1.0")


def run(time_mode: str, steps: int) -> dict[str, object]:
    """Step the sim `steps` times through a TickPlant; timings in ms."""
    sim_exe = Path(get_package_prefix("g2p_sim")) / "lib" / "g2p_sim" / "sim"
    sim = subprocess.Popen(
        [str(sim_exe), "--ros-args", "-p", f"time_mode:={time_mode}", *ENVELOPE_OFF],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    context = Context()
    rclpy.init(context=context)
    node = Node("bench_tick_plant", namespace="/leg", context=context)
    node.set_parameters([Parameter("use_sim_time", value=time_mode == "fast")])
    plant = TickPlant(node, server_timeout_s=60.0)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinner = BackgroundSpinner(executor).start()
    try:
        plant.reset()
        commands = np.random.default_rng(0).uniform(0.2, 0.9, (steps, 3))
        wall = np.empty(steps)
        applied = np.empty((steps, 3))
        for k, command in enumerate(commands):
            t0 = time.perf_counter()
            applied[k] = plant.step(command).activation
            wall[k] = time.perf_counter() - t0
        plant.close()
    finally:
        spinner.stop()
        node.destroy_node()
        rclpy.shutdown(context=context)
        sim.send_signal(2)
        sim.wait(20)
    this = np.all(applied == commands, axis=1)
    previous = np.all(applied[1:] == commands[:-1], axis=1)
    before = np.all(applied[2:] == commands[:-2], axis=1)
    baseline = np.all(applied == BASELINE_ACTIVATION, axis=1)
    ms = wall * 1e3
    return {
        "time_mode": time_mode,
        "steps": steps,
        "step_ms_median": round(float(np.median(ms)), 2),
        "step_ms_p95": round(float(np.percentile(ms, 95)), 2),
        "step_ms_max": round(float(ms.max()), 2),
        "ticks_with_this_command": int(this.sum()),
        "ticks_with_previous_command": int(previous.sum()),
        "ticks_with_the_one_before": int(before.sum()),
        "ticks_at_baseline": int(baseline.sum()),
    }


def main() -> None:
    """Entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1000, help="fast-time steps")
    parser.add_argument("--realtime-steps", type=int, default=400, help="realtime steps (0: skip)")
    args = parser.parse_args()
    print(json.dumps(run("fast", args.steps)))
    if args.realtime_steps:
        print(json.dumps(run("realtime", args.realtime_steps)))


if __name__ == "__main__":
    main()
