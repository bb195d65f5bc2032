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
from g2p.identification.fit import FitConfig
from g2p.identification.segments import load_recorded_run
from g2p.identification.validation import rewards_mm
from g2p.inverse_map import InverseMap
from g2p.learner import LearnerConfig
from g2p.limit_cycle import LimitCycleConfig
from g2p.sim.calibration import LegCalibration
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
    cal = calibrate(
        run, FitConfig(workers=args.workers, max_evaluations=args.max_evaluations), args.fit_babbling_s
    )
    fit_s = time.perf_counter() - t1

    estimates = []
    for e in cal.result.estimates:
        true = truth.value(e.name, e.model_value)
        estimates.append(
            {
                "name": e.name,
                "model": e.model_value,
                "truth": true,
                "estimate": e.value,
                "interval": e.interval,
                "determined": e.determined,
                "error_share": abs(e.value - true) / (abs(true) if true else 1.0),
                "truth_inside": abs(e.value - true) <= e.interval,
            }
        )
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
        for name, c in (("hidden", truth), ("calibrated", cal.calibration), ("model", LegCalibration({})))
    }
    hidden = np.array(rewards["hidden"])

    def rel(name: str) -> list[float]:
        return list(np.abs(np.array(rewards[name]) - hidden) / np.maximum(np.abs(hidden), 1.0))

    args.out.mkdir(parents=True, exist_ok=True)
    write_text_atomically(args.out / "calibration.yaml", cal.calibration.to_yaml())
    write_text_atomically(args.out / "calibration.md", report_markdown(cal))
    plot_angles(cal, args.out / "angles_held_out.png")
    results = {
        "bag": str(bag),
        "babbling_ticks": sum(len(s) for s in run.babbling),
        "attempts": len(run.attempts),
        "record_s": record_s,
        "fit_s": fit_s,
        "evaluations": cal.result.evaluations,
        "rmse_fit_rad": cal.rmse_fit_rad,
        "rmse_held_out_rad": cal.rmse_held_out_rad,
        "estimates": estimates,
        "rewards_mm": rewards,
        "reward_rel_diff": {"calibrated": rel("calibrated"), "model": rel("model")},
    }
    write_text_atomically(args.out / "results.json", json.dumps(results, indent=1))
    print(report_markdown(cal))
    print("| parameter | truth | estimate | +- 95 % | error | truth inside |")
    print("| --- | --- | --- | --- | --- | --- |")
    for e in estimates:
        print(
            f"| {e['name']} | {e['truth']:.5g} | {e['estimate']:.5g} | {e['interval']:.2g} | "
            f"{100 * e['error_share']:.1f} % | {e['truth_inside']} |"
        )
    before, after = cal.rmse_held_out_rad
    print(
        f"held-out RMSE: model {np.degrees(before):.2f} deg, calibrated {np.degrees(after):.2f} deg "
        f"(ratio {after / before:.2f})"
    )
    for name in ("calibrated", "model"):
        r = np.array(rel(name))
        print(
            f"rewards vs hidden, {name}: median {100 * np.median(r):.0f} %, "
            f"within 15 %: {np.sum(r <= 0.15)}/10"
        )
    print(f"recorded in {record_s:.0f} s, fitted in {fit_s:.0f} s ({cal.result.evaluations} evaluations)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
