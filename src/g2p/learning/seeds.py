"""The named random streams of a learning run, all drawn from its one seed.

Each random choice of a run has its own stream, so that changing how much one part draws (a longer
babbling session, more training trajectories) never changes what another part draws. Stream k is the
k-th child of `numpy.random.SeedSequence(seed)`: the same seed gives the same streams, bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np


@dataclass(frozen=True)
class SeedStreams:
    """One generator per random choice of a run.

    Attributes:
        babbling: the babbling activations.
        inverse_map: the inverse map's initial weights and its training/validation splits.
        search: the reward search's proposals.
        tracking: the free-movement experiments' trajectories.
    """

    babbling: np.random.Generator
    inverse_map: np.random.Generator
    search: np.random.Generator
    tracking: np.random.Generator


def seed_streams(seed: int) -> SeedStreams:
    """Fresh generators for every stream of the run seeded `seed` (the field order is the child index)."""
    children = np.random.SeedSequence(seed).spawn(len(fields(SeedStreams)))
    return SeedStreams(*(np.random.default_rng(child) for child in children))
