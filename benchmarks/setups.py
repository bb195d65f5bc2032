"""What the benchmarks share: the variants of the simulated rig and the learner, and single-seed runs.

`bench_learning.py`, `bench_closed_loop.py` and `search_paper_rig.py` import it (run from benchmarks/,
as scripts: their directory is on the path).
"""

from __future__ import annotations

import argparse
import ast
import time
from dataclasses import dataclass, replace
from typing import Any

from g2p.learning.experiments import run_treadmill
from g2p.learning.learner import Learner, LearnerConfig
from g2p.learning.limit_cycle import AIR_FEATURE_BOUNDS, LimitCycleConfig
from g2p.learning.search import SearchConfig
from g2p.rig import PlantRig
from g2p.rig.envelope import EnvelopeConfig, fastest_stop_entries
from g2p.rig.tick_loop import TickLoopConfig
from g2p.sim import AIR_CARRIAGE_HEIGHT_M, MujocoLeg, MujocoLegConfig


@dataclass(frozen=True)
class Setup:
    """What a benchmark run varies from the defaults.

    Attributes:
        overrides: (section, field, value): section "preprocess" or "inverse_map" for LearnerConfig,
            "cycle" for the limit cycles (LimitCycleConfig), "envelope" for the rig's safety envelope
            (EnvelopeConfig).
        model_path: MJCF of the simulated rig; "" = the packaged leg.
        n_train: generalization training trajectories (paper: 30).
        calibration: calibration of the simulated rig (MujocoLegConfig.calibration); "" = none.
    """

    overrides: tuple[tuple[str, str, Any], ...] = ()
    model_path: str = ""
    n_train: int = 30
    calibration: str = ""

    def learner_config(self, seed: int) -> LearnerConfig:
        """The default LearnerConfig with this setup's overrides."""
        cfg = LearnerConfig(seed=seed)
        for section, name, value in self.overrides:
            if section in ("preprocess", "inverse_map"):
                cfg = replace(cfg, **{section: replace(getattr(cfg, section), **{name: value})})
        return cfg

    def cycle(self, bounds: tuple[float, float] | None = None) -> LimitCycleConfig:
        """The default LimitCycleConfig with this setup's overrides, and feature bounds if given."""
        fields = {name: value for section, name, value in self.overrides if section == "cycle"}
        if bounds is not None:
            fields.update(feature_low=bounds[0], feature_high=bounds[1])
        return LimitCycleConfig(**fields)

    def plant(self, seed: int, carriage_height_m: float | None = None) -> PlantRig:
        """A fresh simulated rig for one seed."""
        cfg = MujocoLegConfig(seed=seed, model_path=self.model_path, calibration=self.calibration)
        if carriage_height_m is not None:
            cfg = replace(cfg, carriage_height_m=carriage_height_m)
        envelope = EnvelopeConfig(
            **{name: value for section, name, value in self.overrides if section == "envelope"}
        )
        return PlantRig(MujocoLeg(cfg), config=TickLoopConfig(envelope=envelope))


def parse_override(text: str) -> tuple[str, str, Any]:
    """'preprocess.command_lead_ticks=2' -> ('preprocess', 'command_lead_ticks', 2)."""
    key, sep, raw = text.partition("=")
    section, dot, name = key.partition(".")
    if not sep or not dot or section not in ("preprocess", "inverse_map", "cycle", "envelope"):
        raise argparse.ArgumentTypeError(
            f"expected preprocess.FIELD=VALUE, inverse_map.FIELD=VALUE, cycle.FIELD=VALUE or "
            f"envelope.FIELD=VALUE, got {text!r}"
        )
    try:
        value = ast.literal_eval(raw)
    except (ValueError, SyntaxError):
        value = raw
    return section, name, value


def treadmill(seed: int, setup: Setup = Setup()) -> dict[str, Any]:
    """One treadmill run (paper Fig 4)."""
    t0 = time.perf_counter()
    learner = Learner(setup.learner_config(seed))
    cycle = setup.cycle()
    search = SearchConfig()
    result = run_treadmill(learner, setup.plant(seed), search, cycle)
    wall = time.perf_counter() - t0
    rewards = [r.outcome.reward_mm for r in result.reports]
    first_cross = next((i + 1 for i, r in enumerate(rewards) if r > search.threshold_mm), None)
    at_cross = max(rewards[:first_cross]) if first_cross else float("nan")
    return {
        "seed": seed,
        "crossed": result.crossed_threshold,
        "attempts_to_cross": first_cross,
        "best_reward_mm": result.best_reward_mm,
        "exploitation_improvement_mm": result.best_reward_mm - at_cross,
        "rewards_mm": rewards,
        "energies_j": [r.outcome.energy_j for r in result.reports],
        "tracking_rmse_rad": [r.outcome.tracking.rmse_rad for r in result.reports],
        # Each attempt's fastest (hip, knee) entry into the joint stops: what the envelope may not cut.
        "stop_entry_rad_s": [fastest_stop_entries(r.outcome.recording).tolist() for r in result.reports],
        "phases": [r.phase.value for r in result.reports],
        "fit_s": result.babbling_fit.seconds,
        "refine_s": [r.fit.seconds for r in result.reports if r.fit is not None],
        "wall_s": wall,
    }


def air_learner(seed: int, setup: Setup) -> tuple[Learner, PlantRig, LimitCycleConfig]:
    """A learner that babbled in the air on a fresh rig, the rig, and the air's limit cycles."""
    learner = Learner(setup.learner_config(seed))
    rig = setup.plant(seed, AIR_CARRIAGE_HEIGHT_M)
    learner.babble(rig)
    cycle = setup.cycle(AIR_FEATURE_BOUNDS)
    return learner, rig, cycle
