"""The paper's experiments on the MuJoCo rig, in-process, over many seeds: learning quality and speed.

    scripts/with-env python benchmarks/bench_learning.py --seeds 15 --workers 2 --out docs/results

Runs, for each seed, on a fresh simulated rig (MujocoLeg) with the default configuration:
  treadmill: 5 min of babbling, then exploration until 64 mm and 15 exploitation attempts (paper Fig 4);
  air: babbling in the air, one random trajectory attempted and refined 5 times (paper Fig 5a);
  generalization: babbling in the air, refinement on 30 random trajectories, then the babbling-only and
      the refined map, both fixed, on 30 unseen trajectories (paper Fig 5b).
  bound (only when asked, `--experiments bound`): what the network can reach on the generalization test
      trajectories when it is fitted on their own data, a bound for the generalization figure: the
      babbling-only map plays the 30 test trajectories; a map fitted afresh on babbling + those attempts
      plays them again; a third map, fitted on all of it, plays them once more.
Writes results.json, results.csv (one row per experiment x seed) and figures into --out, and prints a
markdown table beside the paper's figures. The runs fan out on Ray (g2p.rl.sweep): a local Ray using
--workers CPUs (default: all), or a cluster by --address HOST:6379 (or RAY_ADDRESS). A run that fails is
left out of the figures and written to failures.json; the benchmark then exits with status 1.

Variants for measurements (docs/ALGORITHM.md, "Tracking on the simulated rig"):
    --set preprocess.command_lead_ticks=2 --set inverse_map.normalization=zscore   (LearnerConfig fields)
    --set "cycle.radius_rad=(-0.8, 0.75)"   (LimitCycleConfig fields: centre, spoke scale, period)
    --set envelope.soft_limits=False --set envelope.max_step=1.0   (EnvelopeConfig fields: the rig's envelope)
    --model path/to/leg.xml     (another MJCF for the simulated rig)
    --calibration paper         (a calibration of the simulated rig: a file or a packaged name)
    --train 15                  (generalization training trajectories; the paper's 30 by default)
"""

from __future__ import annotations

import argparse
import json
import sys
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from setups import Setup, air_learner, parse_override, treadmill

from g2p.inverse_map import InverseMap
from g2p.learning.attempt import run_attempt
from g2p.learning.experiments import generalization, random_features, refine_one_trajectory
from g2p.learning.kinematics import recording_pairs
from g2p.rl.sweep import SweepResult, ray_session, run_sweep

PAPER = {
    "crossed": "15/15",
    "median_attempts_to_cross": "14-24",
    "median_best_reward_mm": 188.0,
    "median_exploitation_improvement_mm": 45.5,
    "air_median_mse_ratio": "falls every attempt",
    "generalization_reduction": 0.7537,
    "generalization_share_improved": 0.967,
}


def air(seed: int, setup: Setup) -> dict[str, Any]:
    """One trajectory in the air, refined 5 times (paper Fig 5a)."""
    learner, rig, cycle = air_learner(seed, setup)
    rng = learner.streams.tracking
    outcomes = refine_one_trajectory(learner, rig, random_features(rng, cycle, 1)[0], cycle, refinements=5)
    mse = [o.tracking.mse_deg2 for o in outcomes]
    return {"seed": seed, "mse_deg2": mse, "ratio": mse[-1] / mse[0]}


def general(seed: int, setup: Setup) -> dict[str, Any]:
    """Generalization to unseen trajectories (paper Fig 5b)."""
    learner, rig, cycle = air_learner(seed, setup)
    rng = learner.streams.tracking
    train, test = random_features(rng, cycle, 30), random_features(rng, cycle, 30)
    g = generalization(learner, rig, cycle, train[: setup.n_train], test)
    return {
        "seed": seed,
        "babbling_mse_deg2": [e.mse_deg2 for e in g.babbling_map],
        "refined_mse_deg2": [e.mse_deg2 for e in g.refined_map],
        "reduction": g.median_mse_reduction,
        "share_improved": g.share_improved,
    }


def bound(seed: int, setup: Setup) -> dict[str, Any]:
    """The generalization test trajectories tracked by maps fitted on their own data (see the docstring)."""
    learner, rig, cycle = air_learner(seed, setup)
    rng = learner.streams.tracking
    _train, test = random_features(rng, cycle, 30), random_features(rng, cycle, 30)  # as `general` draws
    pre = learner.config.preprocess
    x, y = learner.dataset.arrays()
    inverse_map, mse = learner.frozen_map(), []
    for round_ in range(3):
        outcomes = [run_attempt(rig, inverse_map, f, cycle, learner.lead_ticks) for f in test]
        mse.append([o.tracking.mse_deg2 for o in outcomes])
        if round_ == 2:
            break
        pairs = [recording_pairs(o.recording, pre, pre.transition_fraction) for o in outcomes]
        x = np.vstack([x, *(p.kinematics for p in pairs)])
        y = np.vstack([y, *(p.activation for p in pairs)])
        inverse_map = InverseMap(learner.inverse_map.config)  # fresh weights, a full fit
        inverse_map.fit(x, y, np.random.default_rng([seed, round_]))
    return {"seed": seed, "mse_deg2_by_round": mse}


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
        entries = np.array([e for r in t for e in r["stop_entry_rad_s"]])
        out["max_stop_entry_rad_s"] = entries.max(axis=0).tolist()  # (hip, knee) over every attempt
    a = results.get("air", [])
    if a:
        ratios = [r["ratio"] for r in a]
        out["air_median_mse_ratio"] = float(np.median(ratios))
        # The spread across seeds: single runs range over a factor of ten (docs/ALGORITHM.md).
        out["air_mse_ratio_quartiles"] = np.percentile(ratios, [25, 75]).tolist()
        out["air_share_improved"] = float(np.mean(np.array(ratios) < 1.0))
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
        out["generalization_reduction_per_seed_quartiles"] = np.percentile(
            [r["reduction"] for r in g], [25, 75]
        ).tolist()
    b = results.get("bound", [])
    if b:
        rounds = [np.concatenate([r["mse_deg2_by_round"][k] for r in b]) for k in range(3)]
        out["bound_median_mse_by_round_deg2"] = [float(np.median(m)) for m in rounds]
        out["bound_reduction_by_round"] = [float(1 - np.median(m) / np.median(rounds[0])) for m in rounds[1:]]
        out["bound_share_improved_by_round"] = [float(np.mean(m < rounds[0])) for m in rounds[1:]]
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


RUNNERS = {"treadmill": treadmill, "air": air, "generalization": general, "bound": bound}


def run_experiment(experiment: str, seed: int, setup: Setup) -> dict[str, Any]:
    """One job of the sweep: one seed of one experiment."""
    return RUNNERS[experiment](seed, setup)


def main() -> None:
    """Run the experiments over the seeds and write the results."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=15)
    parser.add_argument(
        "--first-seed", type=int, default=0, help="the seeds are FIRST_SEED, FIRST_SEED + 1, ..."
    )
    parser.add_argument(
        "--workers", type=int, default=None, help="local Ray: CPUs to use, one run each (default: all)"
    )
    parser.add_argument(
        "--address", default=None, help="a Ray cluster's HOST:6379 (default: RAY_ADDRESS, else a local Ray)"
    )
    parser.add_argument("--experiments", default="treadmill,air,generalization")
    parser.add_argument("--out", type=Path, default=Path("docs/results"))
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        type=parse_override,
        default=[],
        metavar="SECTION.FIELD=VALUE",
        help="override a LearnerConfig or LimitCycleConfig field, e.g. preprocess.command_lead_ticks=2 or "
        "cycle.centre_rad=(0.0,-0.75) (repeatable)",
    )
    parser.add_argument("--model", default="", help="MJCF of the simulated rig (default: the packaged leg)")
    parser.add_argument("--train", type=int, default=30, help="generalization training trajectories")
    parser.add_argument(
        "--calibration", default="", help="calibration of the simulated rig: a YAML file or a packaged name"
    )
    args = parser.parse_args()
    experiments = args.experiments.split(",")
    unknown = [name for name in experiments if name not in RUNNERS]
    if unknown:
        parser.error(f"unknown experiments {unknown}; choose from {sorted(RUNNERS)}")
    args.out.mkdir(parents=True, exist_ok=True)
    # Absolute: Ray's workers need not share this working directory (on a cluster, the file must exist
    # at that path on every node).
    model_path = str(Path(args.model).resolve()) if args.model else ""
    calibration = args.calibration
    if calibration and Path(calibration).is_file():
        calibration = str(Path(calibration).resolve())
    setup = Setup(tuple(args.overrides), model_path, args.train, calibration)
    try:  # a bad override fails here, with its name, not in a worker
        setup.learner_config(0)
        setup.cycle()
    except (TypeError, ValueError) as err:
        parser.error(str(err))
    results: dict[str, list[dict[str, Any]]] = {}
    wall_s: dict[str, float] = {}
    sweeps: list[SweepResult] = []
    with ray_session(args.address, args.workers) as workers:
        for name in experiments:
            sweep = run_sweep(
                partial(run_experiment, setup=setup),
                [
                    {"experiment": name, "seed": seed}
                    for seed in range(args.first_seed, args.first_seed + args.seeds)
                ],
                desc=name,
            )
            sweeps.append(sweep)
            results[name] = [{k: v for k, v in row.items() if k != "experiment"} for row in sweep.rows]
            wall_s[name] = sweep.wall_s
            failed = f", {len(sweep.failures)} failed" if sweep.failures else ""
            print(f"{name}: {args.seeds} seeds in {wall_s[name]:.0f} s{failed}", flush=True)
    summary = summarize(results)
    summary["wall_s"] = {**wall_s, "total": sum(wall_s.values())}
    summary["workers"] = workers
    config = {
        "overrides": [list(o) for o in setup.overrides],
        "model": args.model,
        "calibration": args.calibration,
        "train": setup.n_train,
    }
    (args.out / "results.json").write_text(
        json.dumps({"summary": summary, "paper": PAPER, "setup": config, "runs": results}, indent=1)
    )
    table = SweepResult(
        rows=[row for s in sweeps for row in s.rows],
        failures=[f for s in sweeps for f in s.failures],
        wall_s=summary["wall_s"]["total"],
        workers=workers,
        param_columns=("experiment", "seed"),
    )
    table.write_csv(args.out / "results.csv")
    failures_path = args.out / "failures.json"
    if table.failures:
        table.write_failures(failures_path)
    else:
        failures_path.unlink(missing_ok=True)  # a previous run's
    plot(results, args.out)
    for key, value in summary.items():
        print(f"| {key} | {value} | {PAPER.get(key, '')} |")
    for failure in table.failures:
        print(f"failed: {failure.params}: {failure.error}", file=sys.stderr)
    if table.failures:
        print(f"{len(table.failures)} runs failed: {failures_path}", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
