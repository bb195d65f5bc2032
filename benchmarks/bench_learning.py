"""The paper's experiments on the MuJoCo rig, in-process, over many seeds: learning quality and speed.

    scripts/with-env python benchmarks/bench_learning.py --seeds 15 --jobs 2 --out docs/results

Runs, for each seed, on a fresh simulated rig (MujocoLeg) with the default configuration:
  treadmill: 5 min of babbling, then exploration until 64 mm and 15 exploitation attempts (paper Fig 4);
  air: babbling in the air, one random trajectory attempted and refined 5 times (paper Fig 5a);
  generalization: babbling in the air, refinement on 30 random trajectories, then the babbling-only and
      the refined map, both fixed, on 30 unseen trajectories (paper Fig 5b).
Writes results.json and figures into --out, and prints a markdown table beside the paper's figures.
"""

from __future__ import annotations

import argparse
import json
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from g2p.experiments import generalization, random_features, refine_one_trajectory, run_treadmill
from g2p.learner import Learner, LearnerConfig
from g2p.limit_cycle import AIR_FEATURE_BOUNDS, LimitCycleConfig
from g2p.rig import PlantRig
from g2p.search import SearchConfig
from g2p.sim import AIR_CARRIAGE_HEIGHT_M, MujocoLeg, MujocoLegConfig

PAPER = {
    "crossed": "15/15",
    "median_attempts_to_cross": "14-24",
    "median_best_reward_mm": 188.0,
    "median_exploitation_improvement_mm": 45.5,
    "air_mse_ratio": "falls every attempt",
    "generalization_reduction": 0.7537,
    "generalization_share_improved": 0.967,
}


def treadmill(seed: int) -> dict[str, Any]:
    """One treadmill run (paper Fig 4)."""
    t0 = time.perf_counter()
    learner = Learner(LearnerConfig(seed=seed))
    cycle = LimitCycleConfig()
    search = SearchConfig()
    result = run_treadmill(learner, PlantRig(MujocoLeg(MujocoLegConfig(seed=seed))), search, cycle)
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
        "phases": [r.phase.value for r in result.reports],
        "fit_s": result.babbling_fit.seconds,
        "refine_s": [r.fit.seconds for r in result.reports if r.fit is not None],
        "wall_s": wall,
    }


def _air_learner(seed: int) -> tuple[Learner, PlantRig, LimitCycleConfig]:
    learner = Learner(LearnerConfig(seed=seed))
    rig = PlantRig(MujocoLeg(MujocoLegConfig(seed=seed, carriage_height_m=AIR_CARRIAGE_HEIGHT_M)))
    learner.babble(rig)
    cycle = replace(LimitCycleConfig(), feature_low=AIR_FEATURE_BOUNDS[0], feature_high=AIR_FEATURE_BOUNDS[1])
    return learner, rig, cycle


def air(seed: int) -> dict[str, Any]:
    """One trajectory in the air, refined 5 times (paper Fig 5a)."""
    learner, rig, cycle = _air_learner(seed)
    rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(4)[3])
    outcomes = refine_one_trajectory(learner, rig, random_features(rng, cycle, 1)[0], cycle, refinements=5)
    mse = [o.tracking.mse_deg2 for o in outcomes]
    return {"seed": seed, "mse_deg2": mse, "ratio": mse[-1] / mse[0]}


def general(seed: int) -> dict[str, Any]:
    """Generalization to unseen trajectories (paper Fig 5b)."""
    learner, rig, cycle = _air_learner(seed)
    rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(4)[3])
    train, test = random_features(rng, cycle, 30), random_features(rng, cycle, 30)
    g = generalization(learner, rig, cycle, train, test)
    return {
        "seed": seed,
        "babbling_mse_deg2": [e.mse_deg2 for e in g.babbling_map],
        "refined_mse_deg2": [e.mse_deg2 for e in g.refined_map],
        "reduction": g.median_mse_reduction,
        "share_improved": g.share_improved,
    }


def summarize(results: dict[str, list[dict[str, Any]]]) -> dict[str, Any]:
    """The figures to compare with the paper's."""
    out: dict[str, Any] = {}
    t = results.get("treadmill", [])
    if t:
        crossed = [r for r in t if r["crossed"]]
        out["crossed"] = f"{len(crossed)}/{len(t)}"
        to_cross = [r["attempts_to_cross"] for r in crossed]
        out["median_attempts_to_cross"] = float(np.median(to_cross)) if crossed else None
        out["median_best_reward_mm"] = float(np.median([r["best_reward_mm"] for r in t]))
        out["max_best_reward_mm"] = float(np.max([r["best_reward_mm"] for r in t]))
        out["median_exploitation_improvement_mm"] = (
            float(np.median([r["exploitation_improvement_mm"] for r in crossed])) if crossed else None
        )
        out["median_fit_s"] = float(np.median([r["fit_s"] for r in t]))
        out["max_refine_s"] = float(np.max([s for r in t for s in r["refine_s"]]))
        out["median_refine_s"] = float(np.median([s for r in t for s in r["refine_s"]]))
        out["median_run_wall_s"] = float(np.median([r["wall_s"] for r in t]))
    a = results.get("air", [])
    if a:
        out["air_median_mse_ratio"] = float(np.median([r["ratio"] for r in a]))
        out["air_median_mse_by_attempt_deg2"] = np.median([r["mse_deg2"] for r in a], axis=0).tolist()
    g = results.get("generalization", [])
    if g:
        before = np.concatenate([r["babbling_mse_deg2"] for r in g])
        after = np.concatenate([r["refined_mse_deg2"] for r in g])
        out["generalization_median_babbling_mse_deg2"] = float(np.median(before))
        out["generalization_median_refined_mse_deg2"] = float(np.median(after))
        out["generalization_reduction"] = float(1 - np.median(after) / np.median(before))
        out["generalization_share_improved"] = float(np.mean(after < before))
        out["generalization_median_reduction_per_seed"] = float(np.median([r["reduction"] for r in g]))
    return out


def plot(results: dict[str, list[dict[str, Any]]], out: Path) -> None:
    """Fig 4a (reward per attempt, best so far, every seed), Fig 5a and 5b equivalents."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if results.get("treadmill"):
        fig, ax = plt.subplots(figsize=(8, 4.5))
        for r in results["treadmill"]:
            x = np.arange(1, len(r["rewards_mm"]) + 1)
            (line,) = ax.step(x, np.maximum.accumulate(r["rewards_mm"]), where="post", lw=1.2)
            ax.plot(x, r["rewards_mm"], ".", color=line.get_color(), ms=4)
        ax.axhline(64.0, ls=":", color="k", label="threshold 64 mm")
        ax.set(
            xlabel="attempt",
            ylabel="treadmill reward (mm)",
            title="MuJoCo rig: reward per attempt and best so far, one colour per seed",
        )
        ax.legend()
        fig.tight_layout()
        fig.savefig(out / "fig4a_treadmill_seeds.png", dpi=110)
        plt.close(fig)
    if results.get("air") or results.get("generalization"):
        fig, axes = plt.subplots(1, 2, figsize=(10, 4))
        if results.get("air"):
            mse = np.array([r["mse_deg2"] for r in results["air"]])
            axes[0].boxplot(mse, tick_labels=[str(i) for i in range(mse.shape[1])])
            axes[0].set(
                xlabel="refinements",
                ylabel="tracking MSE (deg$^2$)",
                yscale="log",
                title="One trajectory in the air (Fig 5a)",
            )
        if results.get("generalization"):
            before = np.concatenate([r["babbling_mse_deg2"] for r in results["generalization"]])
            after = np.concatenate([r["refined_mse_deg2"] for r in results["generalization"]])
            axes[1].boxplot([before, after], tick_labels=["babbling only", "refined on 30"])
            axes[1].set(
                ylabel="tracking MSE on unseen trajectories (deg$^2$)",
                yscale="log",
                title="Generalization (Fig 5b)",
            )
        fig.tight_layout()
        fig.savefig(out / "fig5_tracking_seeds.png", dpi=110)
        plt.close(fig)


def main() -> None:
    """Run the experiments over the seeds and write the results."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=15)
    parser.add_argument("--jobs", type=int, default=2, help="worker processes")
    parser.add_argument("--experiments", default="treadmill,air,generalization")
    parser.add_argument("--out", type=Path, default=Path("docs/results"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    runners = {"treadmill": treadmill, "air": air, "generalization": general}
    results: dict[str, list[dict[str, Any]]] = {}
    with ProcessPoolExecutor(args.jobs) as pool:
        for name in args.experiments.split(","):
            t0 = time.perf_counter()
            results[name] = list(pool.map(runners[name], range(args.seeds)))
            print(f"{name}: {args.seeds} seeds in {time.perf_counter() - t0:.0f} s", flush=True)
    summary = summarize(results)
    (args.out / "results.json").write_text(
        json.dumps({"summary": summary, "paper": PAPER, "runs": results}, indent=1)
    )
    plot(results, args.out)
    for key, value in summary.items():
        print(f"| {key} | {value} | {PAPER.get(key, '')} |")


if __name__ == "__main__":
    main()
