"""Helpers shared by the MuJoCo plant tests."""

from __future__ import annotations

import numpy as np

from g2p.plant import Plant, Recording, run_sequence

FS_HZ = 78.0


def hold(plant: Plant, activation: tuple[float, float, float], ticks: int) -> Recording:
    """Apply one activation for `ticks` ticks."""
    return run_sequence(plant, np.tile(np.asarray(activation, dtype=np.float64), (ticks, 1)))


def babble(rng: np.random.Generator, ticks: int) -> np.ndarray:
    """Stair-step babbling as in the paper: each motor jumps to U(0.15, 1) with probability 1/fs per tick."""
    out = np.empty((ticks, 3))
    level = rng.uniform(0.15, 1.0, 3)
    for k in range(ticks):
        level = np.where(rng.random(3) < 1.0 / FS_HZ, rng.uniform(0.15, 1.0, 3), level)
        out[k] = level
    return out
