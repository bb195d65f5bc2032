"""Calibration against a hidden rig: record a run on a rig whose leg differs from the model, calibrate on it.

    scripts/with-env python benchmarks/bench_calibration.py --out docs/results/calibration

1. Records a run through the real graph (`bringup --rig sim_air`, the carriage raised) on the hidden rig
   (the simulator loaded with benchmarks/hidden_rig.yaml: 10 parameters changed by stated amounts):
   `--babbling-s` of babbling (the paper's 300 s by default), then `--attempts` attempts in the air, held out.
2. Calibrates the model on the bag's babbling (g2p.identification, as `g2p-calibrate` does), or on its
   first `--fit-babbling-s` seconds.
3. Scores it: each parameter's estimate against the truth, and whether the truth is inside its interval; the
   joint-angle RMSE on the held-out attempts, model vs calibrated; the rewards of 10 random limit cycles
   played on the treadmill, with the run's last map, on the hidden rig, the calibrated rig and the model.

Writes calibration.yaml, calibration.md, results.json and angles_held_out.png into --out; prints a table.
`--fitted FILE` scores a calibration already fitted (steps 1 and 2 skipped with `--bag`).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from g2p.bags.dataset import load_training_data
from g2p.files import write_text_atomically
from g2p.identification.calibrate import calibrate, plot_angles, report_markdown
from g2p.identification.fit import FitConfig, angle_errors_rad, rmse_rad
from g2p.identification.known_answers import rewards_mm
from g2p.identification.segments import load_recorded_run
from g2p.inverse_map import InverseMap
from g2p.learning.learner import LearnerConfig
from g2p.learning.limit_cycle import LimitCycleConfig
from g2p.sim import MujocoLeg
from g2p.sim.calibration import LegCalibration, model_values
from g2p.sim.config import TREADMILL_CARRIAGE_HEIGHT_M, MujocoLegConfig

ROOT = Path(__file__).resolve().parents[1]
HIDDEN = ROOT / "benchmarks" / "hidden_rig.yaml"


def record(bags: Path, run_id: str, hidden: Path, babbling_s: float, attempts: int) -> Path:
    """Record a run on the hidden rig through the graph (bringup, as `make run` does); return the bag."""
    cmd = [
        str(ROOT / "scripts" / "ros2-run"), "g2p_bringup", "bringup", "--rig", "sim_air",
        "--bags-dir", str(bags), "--run-id", run_id,
        "--set", f"rig.leg.calibration={hidden}",
        "--set", f"learner.learner.babbling.duration_s={babbling_s}",
        "--set", f"learner.search.max_exploration_attempts={attempts}",
    ]  # fmt: skip
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return bags / run_id


def main() -> int:
    """Record, calibrate, score."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/results/calibration"))
    parser.add_argument("--bags-dir", type=Path, default=Path("bags/bench"))
    parser.add_argument("--bag", type=Path, default=None, help="calibrate this recorded run instead")
    parser.add_argument("--hidden", type=Path, default=HIDDEN)
    parser.add_argument("--babbling-s", type=float, default=300.0, help="babbling recorded (s)")
    parser.add_argument(
        "--fit-babbling-s", type=float, default=None, help="fit on only the first S s of it (default: all)"
    )
    parser.add_argument("--attempts", type=int, default=5)
    parser.add_argument("--workers", type=int, default=0)
    parser.add_argument("--max-evaluations", type=int, default=FitConfig.max_evaluations)
    parser.add_argument("--fitted", type=Path, default=None, help="score this calibration instead of fitting")
    args = parser.parse_args()
    truth = LegCalibration.load(str(args.hidden.resolve()))
    t0 = time.perf_counter()
    bag = args.bag or record(
        args.bags_dir.resolve(),
        f"hidden-{int(args.babbling_s)}s",
        args.hidden.resolve(),
        args.babbling_s,
        args.attempts,
    )
    record_s = time.perf_counter() - t0
    run = load_recorded_run(bag)
    t1 = time.perf_counter()
    if args.fitted is None:
        fitted = calibrate(
            run, FitConfig(workers=args.workers, max_evaluations=args.max_evaluations), args.fit_babbling_s
        )
        calibration = fitted.calibration
        args.out.mkdir(parents=True, exist_ok=True)
        write_text_atomically(args.out / "calibration.yaml", calibration.to_yaml())
        write_text_atomically(args.out / "calibration.md", report_markdown(fitted))
        plot_angles(fitted, args.out / "angles_held_out.png")
    else:
        calibration = LegCalibration.load(str(args.fitted))
    fit_s = time.perf_counter() - t1
    model_values_ = model_values(MujocoLeg(run.leg_config).model)
    estimates = []
    for name, value in calibration.parameters.items():
        true, interval = truth.value(name, model_values_[name]), calibration.intervals.get(name, float("nan"))
        estimates.append(
            {
                "name": name,
                "model": model_values_[name],
                "truth": true,
                "estimate": value,
                "interval": interval,
                "determined": name not in calibration.undetermined,
                "error_share": abs(value - true) / (abs(true) if true else 1.0),
                "truth_inside": bool(abs(value - true) <= interval),
            }
        )
    held_out = {
        name: rmse_rad(angle_errors_rad(run.attempts, run.leg_config, c))
        for name, c in (("model", LegCalibration({})), ("calibrated", calibration), ("hidden", truth))
    }
    # The same gaits on the treadmill: the run's last map, 10 random limit cycles, three rigs.
    data = load_training_data(bag)
    assert data.inverse_map is not None
    inverse_map = InverseMap.from_arrays(data.inverse_map)
    cycle = LimitCycleConfig()
    features = np.random.default_rng(0).uniform(
        cycle.feature_low, cycle.feature_high, size=(10, cycle.n_spokes)
    )
    lead = LearnerConfig().preprocess.command_lead_ticks
    treadmill = MujocoLegConfig(carriage_height_m=TREADMILL_CARRIAGE_HEIGHT_M)
    rewards = {
        name: rewards_mm(treadmill, c, inverse_map, features, cycle, lead)
        for name, c in (("hidden", truth), ("calibrated", calibration), ("model", LegCalibration({})))
    }
    hidden = np.array(rewards["hidden"])

    def rel(name: str) -> list[float]:
        return list(np.abs(np.array(rewards[name]) - hidden) / np.maximum(np.abs(hidden), 1.0))

    results = {
        "bag": str(bag),
        "babbling_ticks": sum(len(s) for s in run.babbling),
        "attempts": len(run.attempts),
        "record_s": record_s,
        "fit_s": fit_s,
        "fitted": calibration.fit,
        "held_out_rmse_rad": held_out,
        "estimates": estimates,
        "rewards_mm": rewards,
        "reward_rel_diff": {"calibrated": rel("calibrated"), "model": rel("model")},
    }
    write_text_atomically(args.out / "results.json", json.dumps(results, indent=1))
    print("| parameter | truth | estimate | +- 95 % | error | truth inside |")
    print("| --- | --- | --- | --- | --- | --- |")
    for e in estimates:
        print(
            f"| {e['name']} | {e['truth']:.5g} | {e['estimate']:.5g} | {e['interval']:.2g} | "
            f"{100 * e['error_share']:.1f} % | {e['truth_inside']} |"
        )
    before, after = held_out["model"], held_out["calibrated"]
    print(
        f"held-out RMSE ({len(run.attempts)} attempts, open loop from rest): model {np.degrees(before):.2f} "
        f"deg, calibrated {np.degrees(after):.2f} deg (ratio {after / before:.2f}), the hidden rig's own "
        f"{np.degrees(held_out['hidden']):.3f} deg"
    )
    for name in ("calibrated", "model"):
        r = np.array(rel(name))
        print(
            f"rewards vs hidden, {name}: median {100 * np.median(r):.0f} %, "
            f"within 15 %: {np.sum(r <= 0.15)}/10"
        )
    print(f"recorded in {record_s:.0f} s, fitted in {fit_s:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
