"""The adversary's search: the pattern that harms the leg most through an envelope, and its replay.

A black-box search (scipy's differential evolution, no gradients: each candidate is a played pattern)
over the 15 numbers of a `Pattern`, scoring each by its harm on one leg seed (`Harm.score`). The best
pattern found is then replayed on other leg seeds (each seed jitters the ticks differently), so that what
it does is not one run's luck.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import OptimizeResult, differential_evolution
from scipy.stats import qmc

from g2p.adversary.harm import Harm, play_harm
from g2p.adversary.patterns import N_PARAMETERS, Pattern, known_attacks
from g2p.plant import NOMINAL_TICK_HZ
from g2p.rig.envelope import EnvelopeConfig

OBJECTIVES = ("slack", "impact", "tension")
# What a score's share is of: the leg's derail payout and breaking tension (leg.xml), and an entry speed
# into a stop that counts as a blow (rad/s).
LIMITS = {"derail_m": 0.06, "breaking_n": 120.0, "impact_rad_s": 30.0}


@dataclass(frozen=True)
class Attack:
    """The best pattern a search found, with its harm on the leg seed it was scored on.

    Attributes:
        objective: what was sought (OBJECTIVES).
        pattern: the pattern.
        harm: its harm on the search's leg seed.
        evaluations: patterns played by the search.
    """

    objective: str
    pattern: Pattern
    harm: Harm
    evaluations: int


def search(
    envelope: EnvelopeConfig,
    objective: str,
    seed: int = 0,
    seconds: float = 20.0,
    generations: int = 8,
    population: int = 5,
    leg_seed: int = 0,
    progress: Callable[[int, float], None] | None = None,
) -> Attack:
    """Search the patterns for the most harm of one kind through `envelope`.

    Args:
        envelope: the envelope attacked.
        objective: "slack", "impact" or "tension" (`Harm.score`).
        seed: the search's own seed.
        seconds: how long each pattern plays (s).
        generations: differential evolution's generations after the first.
        population: candidates per parameter in each generation (scipy's `popsize`).
        leg_seed: the simulated leg's seed the candidates are scored on.
        progress: called after each generation with the evaluations so far and the best score.
    """
    if objective not in OBJECTIVES:
        raise ValueError(f"objective: must be one of {OBJECTIVES}, got {objective!r}")
    played = 0

    def negative_harm(x: np.ndarray) -> float:
        nonlocal played
        played += 1
        pattern = Pattern.from_unit(np.clip(x, 0.0, 1.0))
        harm = play_harm(pattern.activations(seconds, NOMINAL_TICK_HZ), envelope, leg_seed)
        return -harm.score(objective, LIMITS)

    def after_generation(intermediate_result: OptimizeResult) -> None:
        if progress is not None:
            progress(played, -float(intermediate_result.fun))

    # The first population: Sobol points, with the known attacks among them (the search starts from them).
    size = population * N_PARAMETERS
    first = qmc.Sobol(N_PARAMETERS, seed=seed).random(2 ** math.ceil(math.log2(size)))
    known = np.array([p.to_unit() for p in known_attacks().values()])
    first[: len(known)] = known
    result = differential_evolution(
        negative_harm,
        bounds=[(0.0, 1.0)] * N_PARAMETERS,
        maxiter=generations,
        popsize=population,
        init=first,
        polish=False,
        seed=seed,
        tol=0.0,
        callback=after_generation,
    )
    pattern = Pattern.from_unit(np.clip(result.x, 0.0, 1.0))
    harm = play_harm(pattern.activations(seconds, NOMINAL_TICK_HZ), envelope, leg_seed)
    return Attack(objective, pattern, harm, played)


def replay(pattern_activations: np.ndarray, envelope: EnvelopeConfig, leg_seeds: range) -> list[Harm]:
    """The harm of one activation sequence (N, 3) through `envelope` on each leg seed."""
    return [play_harm(pattern_activations, envelope, s) for s in leg_seeds]
