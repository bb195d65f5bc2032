"""How fast the simulated rig runs, in treadmill and air mode.

Two figures: raw MuJoCo steps per second, and simulated seconds per wall second through `MujocoLeg.step`
(what the learner sees).

    PYTHONPATH=src python benchmarks/bench_physics.py [--seconds 60] [--repeats 3]

The G2P run needs 5 min of babbling plus ~30 attempts of ~20.5 s: about 15 simulated minutes.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import mujoco
import numpy as np

from g2p.plant import NOMINAL_TICK_HZ, run_sequence
from g2p.sim import AIR_CARRIAGE_HEIGHT_M, TREADMILL_CARRIAGE_HEIGHT_M, MujocoLeg, MujocoLegConfig


def babbling(rng: np.random.Generator, ticks: int) -> np.ndarray:
    """Stair-step babbling as in the paper, shape (ticks, 3)."""
    out = np.empty((ticks, 3))
    level = rng.uniform(0.15, 1.0, 3)
    for k in range(ticks):
        level = np.where(rng.random(3) < 1.0 / NOMINAL_TICK_HZ, rng.uniform(0.15, 1.0, 3), level)
        out[k] = level
    return out


def best_of(repeats: int, run: Callable[[], float]) -> float:
    """Smallest wall time of `repeats` runs (s): the least disturbed by other load on the machine."""
    return min(run() for _ in range(repeats))


def bench_raw(height_m: float, steps: int, repeats: int) -> tuple[float, float]:
    """Raw mj_step rate (steps/s) with constant controls, and the physics timestep (s)."""
    plant = MujocoLeg(MujocoLegConfig(carriage_height_m=height_m))
    plant.reset()
    model, data = plant.model, plant.data
    data.ctrl[:] = 0.5

    def run() -> float:
        t0 = time.perf_counter()
        mujoco.mj_step(model, data, steps)
        return time.perf_counter() - t0

    return steps / best_of(repeats, run), float(model.opt.timestep)


def bench_plant(height_m: float, seconds: float, repeats: int) -> float:
    """Simulated seconds per wall second through MujocoLeg.step, on babbling commands."""
    seq = babbling(np.random.default_rng(0), round(seconds * NOMINAL_TICK_HZ))
    plant = MujocoLeg(MujocoLegConfig(carriage_height_m=height_m))

    def run() -> float:
        plant.reset()
        t0 = time.perf_counter()
        run_sequence(plant, seq)
        return time.perf_counter() - t0

    return seconds / best_of(repeats, run)


def main(argv: list[str] | None = None) -> None:
    """Print the figures (see the module docstring)."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seconds", type=float, default=60.0, help="simulated seconds per plant run")
    parser.add_argument("--repeats", type=int, default=3, help="runs per figure (the fastest is kept)")
    args = parser.parse_args(argv)
    print(f"mujoco {mujoco.__version__}, substeps per tick {MujocoLegConfig().substeps}")
    for name, height in (("treadmill", TREADMILL_CARRIAGE_HEIGHT_M), ("air", AIR_CARRIAGE_HEIGHT_M)):
        steps_per_s, dt = bench_raw(height, 20_000, args.repeats)
        rate = bench_plant(height, args.seconds, args.repeats)
        print(
            f"{name:9s}  raw mj_step {steps_per_s:9.0f} steps/s ({steps_per_s * dt:6.0f}x real time at "
            f"dt {dt * 1e3:.2f} ms)   MujocoLeg.step {rate:6.0f} sim-s per wall-s "
            f"({1e3 / rate:5.2f} ms per sim-s)"
        )
    total_s = 5 * 60 + 30 * 20.5
    rate = bench_plant(TREADMILL_CARRIAGE_HEIGHT_M, args.seconds, args.repeats)
    print(
        f"a G2P run (~{total_s / 60:.0f} simulated min) spends ~{total_s / rate:.0f} s of wall time "
        "in the plant"
    )


if __name__ == "__main__":
    main()
