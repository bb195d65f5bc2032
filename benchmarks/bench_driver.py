"""How well the hardware loop keeps 78 Hz and samples the motor currents at 500 Hz, on the fake devices.

The hardware plant (`g2p.hardware.HardwareLeg`) runs on the monotonic clock against the physics-backed
fake buses (`g2p.hardware_fake.buses`: the chips answer byte for byte, the MuJoCo leg moves), playing motor
babbling as in the paper. Two ways to drive it:

    plant       the plant alone, stepped back to back (the loop's own timing);
    rig_server  the plant inside the ROS rig server on an in-process node, publishing every tick on
                real Fast DDS: what the driver node does (its tick loop thread, Pacing.PLANT).

Figures: the tick period error (period - 1/78 s: mean, p99 and max of its magnitude), ticks late by a
whole period, and the current-sampling rate achieved against 500 Hz.

    source scripts/env.sh
    python benchmarks/bench_driver.py [--seconds 60] [--mode plant|rig_server|both] [--sched-fifo 0]
                                      [--rig-config wiring.yaml]   # on the Pi: the real devices

On the Pi the buses add their transfer times (about 0.1 ms per INA219 word at 400 kHz I2C); here the
fake chips and the MuJoCo physics cost CPU instead. On a loaded machine, expect outliers in p99 and max.
"""

from __future__ import annotations

import argparse
import os
import threading
import time
from dataclasses import dataclass

import numpy as np

from g2p.hardware import HardwareLeg, HardwareLegConfig, WiringConfig, load_wiring, open_devices
from g2p.hardware_fake.buses import fake_devices
from g2p.plant import NOMINAL_TICK_HZ, FloatArray, TickSample


def babbling(rng: np.random.Generator, ticks: int) -> FloatArray:
    """Stair-step babbling as in the paper, shape (ticks, 3)."""
    out = np.empty((ticks, 3))
    level = rng.uniform(0.15, 1.0, 3)
    for k in range(ticks):
        level = np.where(rng.random(3) < 1.0 / NOMINAL_TICK_HZ, rng.uniform(0.15, 1.0, 3), level)
        out[k] = level
    return out


@dataclass(frozen=True)
class Figures:
    """What one run measured.

    Attributes:
        mode: how the plant was driven.
        ticks: ticks measured.
        rate_hz: ticks per second of stamps.
        mean_error_ms: mean of (period - 1/78 s) (ms).
        p99_error_ms: 99th percentile of |period - 1/78 s| (ms).
        max_error_ms: largest |period - 1/78 s| (ms).
        late_ticks: ticks that ran past the next deadline (the loop re-synchronised).
        current_rate_hz: current-sensor sampling rounds per second achieved (target 500 Hz).
        cpu_fraction: process CPU time over wall time.
    """

    mode: str
    ticks: int
    rate_hz: float
    mean_error_ms: float
    p99_error_ms: float
    max_error_ms: float
    late_ticks: int
    current_rate_hz: float
    cpu_fraction: float

    def line(self) -> str:
        """One line of the report."""
        return (
            f"{self.mode:>10}: {self.ticks} ticks at {self.rate_hz:.2f} Hz; period error mean "
            f"{self.mean_error_ms:+.3f} ms, p99 {self.p99_error_ms:.3f} ms, max {self.max_error_ms:.3f} ms; "
            f"{self.late_ticks} late ticks; currents sampled at {self.current_rate_hz:.1f} Hz (target 500); "
            f"CPU {100 * self.cpu_fraction:.0f}%"
        )


def figures(mode: str, stamps: FloatArray, leg: HardwareLeg, cpu_fraction: float) -> Figures:
    """Period statistics from tick stamps (s)."""
    periods = np.diff(stamps)
    error = periods - 1.0 / NOMINAL_TICK_HZ
    return Figures(
        mode=mode,
        ticks=len(periods),
        rate_hz=len(periods) / float(stamps[-1] - stamps[0]),
        mean_error_ms=1e3 * float(np.mean(error)),
        p99_error_ms=1e3 * float(np.percentile(np.abs(error), 99)),
        max_error_ms=1e3 * float(np.max(np.abs(error))),
        late_ticks=leg.counters.late_ticks,
        current_rate_hz=leg.counters.current_sample_rate_hz,
        cpu_fraction=cpu_fraction,
    )


def make_leg(sched_fifo: int, wiring: str = "") -> HardwareLeg:
    """The hardware plant on the monotonic clock, quick to reset: on fake devices, or the real ones."""
    if wiring:
        wiring = load_wiring(wiring)
        devices = open_devices(wiring)
    else:
        wiring = WiringConfig()
        _, devices = fake_devices(wiring)
    config = HardwareLegConfig(sched_fifo_priority=sched_fifo, dither_amplitude=0.0, settle_min_s=0.2)
    return HardwareLeg(devices, wiring, config)


def run_plant(seconds: float, sched_fifo: int, seed: int, wiring: str = "") -> Figures:
    """Step the plant back to back for `seconds` (s) of babbling."""
    leg = make_leg(sched_fifo, wiring)
    try:
        leg.reset()
        seq = babbling(np.random.default_rng(seed), round(seconds * NOMINAL_TICK_HZ))
        leg.counters.late_ticks = 0
        c0, w0 = time.process_time(), time.monotonic()
        stamps = np.array([leg.step(row).t_s for row in seq])
        cpu = (time.process_time() - c0) / (time.monotonic() - w0)
        return figures("plant", stamps, leg, cpu)
    finally:
        leg.close()


class _StampingPlant:
    """A plant proxy that records the stamp of every step (the rig server's loop calls it)."""

    def __init__(self, leg: HardwareLeg) -> None:
        self.leg = leg
        self.stamps: list[float] = []

    @property
    def tick_hz(self) -> float:
        return self.leg.tick_hz

    def reset(self) -> TickSample:
        return self.leg.reset()

    def step(self, activation: FloatArray) -> TickSample:
        sample = self.leg.step(activation)
        self.stamps.append(sample.t_s)
        return sample

    def close(self) -> None:
        self.leg.close()


def run_rig_server(seconds: float, sched_fifo: int, seed: int, wiring: str = "") -> Figures:
    """Play `seconds` (s) of babbling through the rig server's run_activations, in one process."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import MultiThreadedExecutor
    from rclpy.node import Node

    from g2p.rig.tick_loop import Pacing
    from g2p_interfaces.action import RunActivations
    from g2p_ros import contract
    from g2p_ros.action_client import ActionClient
    from g2p_ros.rig_server import RigServer

    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = Context()
    rclpy.init(context=context)
    node = Node("bench_driver", namespace="/bench_leg", context=context)
    executor = MultiThreadedExecutor(num_threads=3, context=context)
    executor.add_node(node)
    plant = _StampingPlant(make_leg(sched_fifo, wiring))
    server = RigServer(node, plant, Pacing.PLANT)  # type: ignore[arg-type]
    client = ActionClient(node, RunActivations, contract.RUN_ACTIVATIONS)
    spinner = threading.Thread(target=executor.spin, daemon=True)  # after the entities exist
    spinner.start()
    try:
        server.start()
        assert client.wait_for_server(timeout_sec=10.0), "the rig server's action did not appear"
        seq = babbling(np.random.default_rng(seed), round(seconds * NOMINAL_TICK_HZ))
        done = threading.Event()
        plant.stamps.clear()
        plant.leg.counters.late_ticks = 0
        c0, w0 = time.process_time(), time.monotonic()
        goal = client.send_goal_async(RunActivations.Goal(activation=seq.ravel()))
        goal.add_done_callback(
            lambda f: f.result().get_result_async().add_done_callback(lambda _: done.set())
        )
        if not done.wait(seconds * 2 + 30):
            raise RuntimeError("the sequence did not finish")
        cpu = (time.process_time() - c0) / (time.monotonic() - w0)
        stamps = np.array(plant.stamps[: len(seq)])
        result = figures("rig_server", stamps, plant.leg, cpu)
        print(result.line(), flush=True)  # before the teardown
        return result
    finally:
        client.destroy()
        server.destroy()
        plant.close()
        executor.shutdown(timeout_sec=5.0)
        spinner.join(5.0)
        node.destroy_node()
        rclpy.shutdown(context=context)


def main() -> None:
    """Run the benchmark and print its figures."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seconds", type=float, default=60.0, help="babbling played per mode (s)")
    parser.add_argument("--mode", choices=["plant", "rig_server", "both"], default="both")
    parser.add_argument("--sched-fifo", type=int, default=0, help="SCHED_FIFO priority of the tick thread")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--rig-config",
        default="",
        help="on the Pi: the rig YAML, to measure the real devices instead of the fakes",
    )
    args = parser.parse_args()
    print(
        f"tick target {NOMINAL_TICK_HZ:g} Hz ({1e3 / NOMINAL_TICK_HZ:.3f} ms), {args.seconds:g} s per mode, "
        f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}"
    )
    if args.mode in ("plant", "both"):
        print(run_plant(args.seconds, args.sched_fifo, args.seed, args.wiring).line(), flush=True)
    if args.mode in ("rig_server", "both"):
        run_rig_server(args.seconds, args.sched_fifo, args.seed, args.wiring)
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
