"""Measure what closed loop adds to each tick of the rig's loop: the per-tick decision of run_trajectory.

The rig server (g2p_ros.rig_server, both the simulator and the driver) decides each closed-loop tick's
activation as `g2p.rig.closed_loop.TrajectoryTracker.next_activation(previous tick's sample)` followed by the
check every activation gets (`g2p.safety.check_activation_sequence` on the row). This times exactly that,
call by call, with nothing else running in the process: the map's numpy forward pass on one row, the
feedback law, the delay queue. No MuJoCo, no torch, no ROS: it runs on the Pi as it is.

The map is `g2p.inverse_map.random_map` (seeded weights, the paper's 15 hidden units by default; the
cost does not depend on the values); the trajectory is 20 cycles of a 10-spoke limit cycle (1600 ticks),
fed samples whose angles and velocities are the desired ones plus a fixed error, so that every term of the
law works.

Run:  PYTHONPATH=src python benchmarks/bench_rig_loop_cost.py [--trajectories 20] [--hidden 15]
      [--delay-ticks 0]
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np

from g2p.inverse_map import random_map
from g2p.learning.limit_cycle import LimitCycleConfig, attempt_kinematics
from g2p.plant import NOMINAL_TICK_HZ, TickSample
from g2p.rig.closed_loop import FeedbackConfig, Trajectory, TrajectoryTracker
from g2p.safety import check_activation_sequence


def samples_for(desired: np.ndarray) -> list[TickSample]:
    """One sample per tick: the desired angles and velocities plus a fixed error (0.05 rad, 0.3 rad/s)."""
    zeros3 = np.zeros(3)
    return [
        TickSample(
            t_s=k / NOMINAL_TICK_HZ,
            activation=zeros3,
            position_rad=row[:2] + 0.05,
            velocity_rad_s=row[2:4] - 0.3,
            belt_mm=0.0,
            belt_velocity_mm_s=0.0,
            current_a=zeros3,
            power_w=zeros3,
            energy_j=zeros3,
        )
        for k, row in enumerate(desired)
    ]


def time_ticks(trajectory: Trajectory, samples: list[TickSample], check: bool) -> np.ndarray:
    """Wall time of each tick's decision (ns), one trajectory played through a fresh tracker."""
    tracker = TrajectoryTracker(trajectory, 1.0 / NOMINAL_TICK_HZ)
    out = np.empty(len(trajectory), dtype=np.int64)
    clock = time.perf_counter_ns
    for k in range(len(trajectory)):
        previous = samples[k - 1] if k else None
        t0 = clock()
        activation = tracker.next_activation(previous)
        if check:
            check_activation_sequence(activation[np.newaxis])
        out[k] = clock() - t0
    return out


def main() -> None:
    """Time each tick's decision and print median, 99th percentile and maximum (us)."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--trajectories", type=int, default=20, help="trajectories of 1600 ticks timed")
    parser.add_argument("--hidden", type=int, default=15, help="hidden units of the map")
    parser.add_argument("--delay-ticks", type=int, default=0, help="the feedback's sensor delay (ticks)")
    args = parser.parse_args()

    desired = attempt_kinematics(np.linspace(0.3, 0.9, 10), LimitCycleConfig(n_cycles=20))
    feedback = FeedbackConfig(
        p_gain_per_s=(10.0, 15.0),
        i_gain_per_s2=(6.0, 9.0),
        velocity_gain=(3.0, 3.0),
        delay_ticks=args.delay_ticks,
    )
    trajectory = Trajectory(
        desired, random_map(np.random.default_rng(0), args.hidden), feedback, lead_ticks=3
    )
    samples = samples_for(desired)
    print(
        f"{platform.machine()} {platform.python_implementation()} {platform.python_version()}, "
        f"numpy {np.__version__}; map 6-{args.hidden}-3, {len(trajectory)} ticks x {args.trajectories} "
        f"trajectories, delay {args.delay_ticks} ticks; tick period {1e6 / NOMINAL_TICK_HZ:.0f} us"
    )
    for label, check in (
        ("TrajectoryTracker.next_activation", False),
        ("  + check_activation_sequence (the rig server's tick)", True),
    ):
        time_ticks(trajectory, samples, check)  # warm-up
        ns = np.concatenate([time_ticks(trajectory, samples, check) for _ in range(args.trajectories)])
        us = ns / 1e3
        print(
            f"{label:55s} median {np.median(us):6.1f} us  p99 {np.percentile(us, 99):6.1f} us  "
            f"max {us.max():7.1f} us  ({us.size} ticks)"
        )


if __name__ == "__main__":
    main()
