"""The adversary's search: the sequence that harms the leg most through an envelope, and its replay.

A black-box search over one space of activation sequences (g2p.adversary.patterns.SPACES: "periodic"
patterns or free "steps"), scoring each candidate by its harm (`Harm.score`) played on one leg seed. It is
CMA-ES (the `cma` package) in the space's unit cube, restarted with a doubled population whenever it
converges (IPOP) until its budget of played sequences is spent. The first run starts from the best of the
known attacks in the periodic space, and from a random point among the steps; each restart from a random
point. The best sequence found is then replayed on other leg seeds (each seed jitters the ticks
differently), so that what it does is not one run's luck.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cma
import numpy as np

from g2p.adversary.harm import Harm, play_harm, play_harm_in_env
from g2p.adversary.patterns import SPACES, Pattern, Space, known_attacks
from g2p.plant import NOMINAL_TICK_HZ, FloatArray
from g2p.rig.envelope import EnvelopeConfig

OBJECTIVES = ("slack", "impact", "tension")
# What a score's share is of: the leg's derail payout and breaking tension (leg.xml), and an entry speed
# into a stop that counts as a blow (rad/s).
LIMITS = {"derail_m": 0.06, "breaking_n": 120.0, "impact_rad_s": 30.0}
# CMA-ES's first step size in the unit cube: a third of each parameter's range.
SIGMA0 = 0.3


@dataclass(frozen=True)
class Attack:
    """The best sequence a search found, with its harm on the leg seed it was scored on.

    Attributes:
        objective: what was sought (OBJECTIVES).
        space: the space searched ("periodic" or "steps").
        sequence: the best sequence.
        harm: its harm on the search's leg seed.
        evaluations: sequences played by the search.
        restarts: CMA-ES runs after the first.
    """

    objective: str
    space: str
    sequence: Space
    harm: Harm
    evaluations: int
    restarts: int


def search(
    envelope: EnvelopeConfig,
    objective: str,
    space: str = "periodic",
    seed: int = 0,
    seconds: float = 20.0,
    evaluations: int = 100,
    leg_seed: int = 0,
    calibration: str = "",
    progress: Callable[[int, float], None] | None = None,
) -> Attack:
    """Search one space for the most harm of one kind through `envelope`.

    Args:
        envelope: the envelope attacked.
        objective: "slack", "impact" or "tension" (`Harm.score`).
        space: "periodic" or "steps" (g2p.adversary.patterns.SPACES).
        seed: the search's own seed.
        seconds: how long each sequence plays (s).
        evaluations: sequences to play in all (the budget; a generation begun is played whole).
        leg_seed: the simulated leg's seed the candidates are scored on.
        calibration: the simulated rig ("" the default, "paper" sim_paper).
        progress: called after each CMA-ES generation with the evaluations so far and the best score.
    """
    if objective not in OBJECTIVES:
        raise ValueError(f"objective: must be one of {OBJECTIVES}, got {objective!r}")
    if space not in SPACES:
        raise ValueError(f"space: must be one of {tuple(SPACES)}, got {space!r}")
    kind = SPACES[space]
    rng = np.random.default_rng(seed)
    played = 0

    def score(x: FloatArray) -> float:
        nonlocal played
        played += 1
        activations = kind.from_unit(x).activations(seconds, NOMINAL_TICK_HZ)
        return play_harm(activations, envelope, leg_seed, calibration).score(objective, LIMITS)

    best_x, best = rng.random(kind.n_parameters), -np.inf
    if kind is Pattern:  # start from the best known attack
        for x in (p.to_unit() for p in known_attacks().values()):
            if (f := score(x)) > best:
                best_x, best = x, f
    x0, population, restarts = best_x, 4 + int(3 * np.log(kind.n_parameters)), -1
    while played < evaluations:
        restarts += 1
        options = {
            "bounds": [0.0, 1.0],
            "popsize": population,
            "seed": int(rng.integers(1, 2**31)),  # cma seeds numpy's global generator with it
            "maxfevals": evaluations - played,
            "verbose": -9,
        }
        es = cma.CMAEvolutionStrategy(x0, SIGMA0, options)
        while not es.stop() and played < evaluations:
            xs = [np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0) for x in es.ask()]
            fs = [score(x) for x in xs]
            es.tell(xs, [-f for f in fs])
            if max(fs) > best:
                best, best_x = max(fs), xs[int(np.argmax(fs))]
            if progress is not None:
                progress(played, best)
        x0, population = rng.random(kind.n_parameters), 2 * population
    sequence = kind.from_unit(best_x)
    harm = play_harm(sequence.activations(seconds, NOMINAL_TICK_HZ), envelope, leg_seed, calibration)
    return Attack(objective, space, sequence, harm, played, restarts)


def replay(
    activations: FloatArray,
    envelope: EnvelopeConfig,
    leg_seeds: range,
    calibration: str = "",
    through_env: bool = False,
) -> list[Harm]:
    """The harm of one activation sequence (N, 3) through `envelope` on each leg seed.

    Played through `PlantRig`, or (`through_env`) as an episode of `g2p/Treadmill-v0`.
    """
    if through_env:
        return [play_harm_in_env(activations, envelope, s, calibration) for s in leg_seeds]
    return [play_harm(activations, envelope, s, calibration) for s in leg_seeds]
