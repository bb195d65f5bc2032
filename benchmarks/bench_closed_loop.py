"""Closed-loop G2P (g2p.rig.closed_loop) against the paper's open loop on the MuJoCo rig, over many seeds.

    scripts/with-env python benchmarks/bench_closed_loop.py --seeds 15 --workers 2 --out docs/results

Experiments (`--experiments`, comma-separated; default air,treadmill):
  sweep: the feedback gains on the air task: per seed, the babbling-only map (5 min of babbling in the air,
      as bench_learning) on 10 random air trajectories (the first 10 of the generalization experiment's
      training draw, never its test trajectories), median tracking RMSE for a grid of (V, P, I) with no
      delay and a smaller grid with 4 and 8 ticks of delay, then a finer grid around the best. Writes
      closed_loop_sweep.json (not run by default: it chose CHOSEN_GAINS below).
  air: per seed, babbling in the air; the babbling-only map (a frozen copy) and the map refined on 30
      training trajectories (open-loop attempts, refined after each, as bench_learning's generalization);
      then the 30 unseen test trajectories with both maps, each in open loop, closed loop with the
      follow-up's gains, with the chosen gains, and with the chosen gains for 4 and 8 ticks of delay (51
      and 103 ms at 78 Hz), and the follow-up's gains with 8 ticks.
  treadmill: the learning run (bench_learning's treadmill) with every attempt in open loop and in closed
      loop with the chosen gains.
Writes closed_loop.json and figures into --out and prints a markdown table beside the follow-up's figures
(Marjaninejad et al. 2019, arXiv 1907.04539; simulated leg at 200 Hz).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from setups import Setup, air_learner, treadmill

from g2p.learning.attempt import AttemptOutcome, run_attempt
from g2p.learning.experiments import random_features
from g2p.learning.learner import LearnerConfig
from g2p.plant import NOMINAL_TICK_HZ
from g2p.rig.closed_loop import ControlMode, FeedbackConfig
from g2p.rl.sweep import JobFailure, ray_session, run_sweep

KNEE_SCALE = 1.5
"""The distal joint's P and I gains are the proximal's times this (the follow-up's P: 10, 15)."""

FOLLOW_UP = FeedbackConfig(p_gain_per_s=(10.0, 15.0), i_gain_per_s2=(2.0, 6.0), velocity_gain=(0.0, 0.0))
"""The follow-up's law: PI on the angle error, no velocity term."""


def gains(v: float, p: float, i: float, delay_ticks: int = 0, **limits: float) -> FeedbackConfig:
    """A feedback law of the sweep: V equal on both joints, the distal P and I scaled by KNEE_SCALE."""
    return FeedbackConfig(
        p_gain_per_s=(p, KNEE_SCALE * p),
        i_gain_per_s2=(i, KNEE_SCALE * i),
        velocity_gain=(v, v),
        delay_ticks=delay_ticks,
        **limits,
    )


# The sweep's grids: (V, P, I) without delay, and with delay.
SWEEP_GRID = [(v, p, i) for v in (0.0, 1.0, 2.0, 3.0, 4.0) for p in (0.0, 2.0, 5.0) for i in (0.0, 2.0, 6.0)]
SWEEP_DELAY_GRID = [(v, p, i) for v in (0.0, 0.5, 1.0, 1.5, 2.0, 3.0) for p in (0.0, 2.0) for i in (0.0, 2.0)]
# The second stage: around the best laws of the first (P never helped there): V x I, P = 0; and whether
# the correction limit, which binds at V >= 3, costs anything.
SWEEP_FINE_GRID = {
    0: [(v, 0.0, i) for v in (3.0, 4.0, 5.0, 6.0) for i in (2.0, 4.0, 6.0, 10.0)],
    4: [(v, 0.0, i) for v in (1.0, 1.5, 2.0) for i in (2.0, 4.0, 6.0)],
    8: [(v, 0.0, i) for v in (0.5, 1.0, 1.5) for i in (2.0, 4.0, 6.0)],
}
SWEEP_DELAYS = (0, 4, 8)
SWEEP_TRAJECTORIES = 10

# The gains chosen by the sweep (closed_loop_sweep.json), per feedback delay (ticks): the lowest V within
# noise of the best median RMSE; P = 0, I = (4, 6) at every delay.
CHOSEN_GAINS = {
    0: gains(3.0, 0.0, 4.0),
    4: gains(1.5, 0.0, 4.0, delay_ticks=4),
    8: gains(1.0, 0.0, 4.0, delay_ticks=8),
}

# The follow-up's figures (simulation, tracking RMSE in rad).
FOLLOW_UP_PAPER = {
    "air_open_rmse_rad": 0.373,
    "air_closed_rmse_rad": 0.099,
    "contact_open_rmse_rad": 0.376,
    "contact_closed_rmse_rad": 0.131,
    "air_closed_100ms_rmse_rad": 0.305,
}


def _rounded(obj: Any, digits: int = 4) -> Any:
    """JSON data with every float to `digits` significant digits (a smaller file; no loss that matters)."""
    if isinstance(obj, float):
        return float(f"{obj:.{digits}g}")
    if isinstance(obj, dict):
        return {k: _rounded(v, digits) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_rounded(v, digits) for v in obj]
    return obj


def _describe(fb: FeedbackConfig | None) -> dict[str, Any] | None:
    return None if fb is None else asdict(fb)


def _clip_shares(outcome: AttemptOutcome, fb: FeedbackConfig) -> tuple[float, float]:
    """Shares of the second half's ticks (either joint) at the correction limit and at the integral limit.

    The integral is rebuilt from the recording as the tracker integrates it (the same clipped sum of the
    angle errors, its delay aside).
    """
    assert outcome.correction_rad_s is not None
    n = len(outcome.desired)
    half = slice(n // 2, None)
    at_correction = np.abs(outcome.correction_rad_s[half]) >= fb.correction_limit_rad_s - 1e-9
    errors = outcome.desired[:, :2] - outcome.recording.position_rad
    integral, values = np.zeros(2), np.zeros((n, 2))
    for k, e in enumerate(errors):
        integral = np.clip(integral + e / NOMINAL_TICK_HZ, -fb.integral_limit_rad_s, fb.integral_limit_rad_s)
        values[k] = integral
    at_integral = np.abs(values[half]) >= fb.integral_limit_rad_s - 1e-9
    uses_integral = any(g > 0 for g in fb.i_gain_per_s2)
    return float(np.mean(at_correction)), float(np.mean(at_integral)) if uses_integral else 0.0


def _sweep_task(seed: int, delay_ticks: int, stage: str) -> dict[str, Any]:
    """One seed and one delay of the sweep: the babbling-only map on the sweep's trajectories."""
    delay = delay_ticks
    t0 = time.perf_counter()
    learner, rig, cycle = air_learner(seed, Setup())
    inverse_map = learner.frozen_map()
    rng = learner.streams.tracking
    features = random_features(rng, cycle, 30)[:SWEEP_TRAJECTORIES]  # the generalization's training draw
    laws: list[FeedbackConfig | None] = []
    if stage == "coarse":
        if delay == 0:
            laws += [None]
        laws += [gains(v, p, i, delay) for v, p, i in (SWEEP_GRID if delay == 0 else SWEEP_DELAY_GRID)]
        laws += [replace(FOLLOW_UP, delay_ticks=delay)]
    else:
        first = set(SWEEP_GRID if delay == 0 else SWEEP_DELAY_GRID)
        laws += [gains(v, p, i, delay) for v, p, i in SWEEP_FINE_GRID[delay] if (v, p, i) not in first]
        if delay == 0:
            laws += [gains(v, 0.0, 6.0, correction_limit_rad_s=20.0) for v in (3.0, 4.0, 5.0)]
    rows = []
    for fb in laws:
        outcomes = [
            run_attempt(rig, inverse_map, f, cycle, learner.lead_ticks, feedback=fb) for f in features
        ]
        shares = [_clip_shares(o, fb) for o in outcomes] if fb is not None else [(0.0, 0.0)]
        rows.append(
            {
                "feedback": _describe(fb),
                "rmse_rad": [o.tracking.rmse_rad for o in outcomes],
                "correction_limit_share": float(np.mean([s[0] for s in shares])),
                "integral_limit_share": float(np.mean([s[1] for s in shares])),
            }
        )
    return {
        "seed": seed,
        "delay_ticks": delay,
        "stage": stage,
        "rows": rows,
        "wall_s": time.perf_counter() - t0,
    }


def _law_key(fb: dict[str, Any] | None) -> str:
    if fb is None:
        return "open loop"
    p, i, v = fb["p_gain_per_s"], fb["i_gain_per_s2"], fb["velocity_gain"]
    key = f"V={v[0]:g},{v[1]:g} P={p[0]:g},{p[1]:g} I={i[0]:g},{i[1]:g} delay={fb['delay_ticks']}"
    default = FeedbackConfig()
    if fb["correction_limit_rad_s"] != default.correction_limit_rad_s:
        key += f" correction limit {fb['correction_limit_rad_s']:g}"
    if fb["integral_limit_rad_s"] != default.integral_limit_rad_s:
        key += f" integral limit {fb['integral_limit_rad_s']:g}"
    return key


def summarize_sweep(tasks: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per law: median RMSE per seed and over every seed's trajectories, sorted by delay then median."""
    by_law: dict[str, dict[str, Any]] = {}
    for task in tasks:
        for row in task["rows"]:
            key = _law_key(row["feedback"])
            entry = by_law.setdefault(
                key,
                {
                    "law": key,
                    "feedback": row["feedback"],
                    "delay_ticks": task["delay_ticks"],
                    "per_seed": {},
                    "all": [],
                    "clip": [],
                },
            )
            entry["per_seed"][task["seed"]] = float(np.median(row["rmse_rad"]))
            entry["all"] += row["rmse_rad"]
            entry["clip"].append((row["correction_limit_share"], row["integral_limit_share"]))
    out = []
    for entry in by_law.values():
        out.append(
            {
                "law": entry["law"],
                "feedback": entry["feedback"],
                "delay_ticks": entry["delay_ticks"],
                "median_rmse_rad": float(np.median(entry["all"])),
                "median_rmse_rad_per_seed": [entry["per_seed"][s] for s in sorted(entry["per_seed"])],
                "worst_seed_median_rmse_rad": max(entry["per_seed"].values()),
                "correction_limit_share": float(np.mean([c[0] for c in entry["clip"]])),
                "integral_limit_share": float(np.mean([c[1] for c in entry["clip"]])),
            }
        )
    return sorted(out, key=lambda r: (r["delay_ticks"], r["median_rmse_rad"]))


def print_sweep(rows: list[dict[str, Any]], top: int = 8) -> str:
    """A markdown table of the best laws per delay (and the open loop and the follow-up's law)."""
    lines = [
        "| delay (ticks) | law | median RMSE (rad) | per seed | correction / integral at limit |",
        "| --- | --- | --- | --- | --- |",
    ]
    for delay in sorted({r["delay_ticks"] for r in rows}):
        mine = [r for r in rows if r["delay_ticks"] == delay]
        ref = [r for r in mine if r["feedback"] is None or r["feedback"]["velocity_gain"][0] == 0]
        shown = mine[:top] + [
            r for r in ref if r not in mine[:top] and r["law"].startswith(("open", "V=0,0 P=10"))
        ]
        for r in shown:
            seeds = ", ".join(f"{x:.3f}" for x in r["median_rmse_rad_per_seed"])
            lines.append(
                f"| {delay} | {r['law']} | {r['median_rmse_rad']:.3f} | {seeds} | "
                f"{r['correction_limit_share']:.1%} / {r['integral_limit_share']:.1%} |"
            )
    return "\n".join(lines)


@dataclass(frozen=True)
class LoopSetup(Setup):
    """setups.Setup with the learner's control mode: None = open loop, else closed loop."""

    feedback: FeedbackConfig | None = None

    def learner_config(self, seed: int) -> LearnerConfig:
        """The default LearnerConfig, in closed loop with `feedback` when given."""
        cfg = super().learner_config(seed)
        if self.feedback is None:
            return cfg
        return replace(cfg, control=ControlMode.CLOSED, feedback=self.feedback)


def air_laws() -> dict[str, FeedbackConfig | None]:
    """The control laws the air experiment compares, by name."""
    return {
        "open": None,
        "follow_up": FOLLOW_UP,
        "chosen": CHOSEN_GAINS[0],
        "chosen_delay4": CHOSEN_GAINS[4],
        "chosen_delay8": CHOSEN_GAINS[8],
        "follow_up_delay8": replace(FOLLOW_UP, delay_ticks=8),
    }


def air(seed: int) -> dict[str, Any]:
    """Babbling-only and refined map on 30 unseen air trajectories, in every control law (see above)."""
    t0 = time.perf_counter()
    learner, rig, cycle = air_learner(seed, Setup())
    babbling_map = learner.frozen_map()
    rng = learner.streams.tracking
    train, test = random_features(rng, cycle, 30), random_features(rng, cycle, 30)  # as bench_learning
    train_rmse = [learner.attempt(rig, f, cycle, True)[0].tracking.rmse_rad for f in train]  # open loop
    maps = {"babbling": babbling_map, "refined": learner.frozen_map()}
    out: dict[str, Any] = {"seed": seed, "train_rmse_rad": train_rmse, "maps": {}}
    for map_name, inverse_map in maps.items():
        out["maps"][map_name] = {}
        for law, fb in air_laws().items():
            outcomes = [
                run_attempt(rig, inverse_map, f, cycle, learner.lead_ticks, feedback=fb) for f in test
            ]
            entry: dict[str, Any] = {
                "rmse_rad": [o.tracking.rmse_rad for o in outcomes],
                "mse_deg2": [o.tracking.mse_deg2 for o in outcomes],
            }
            if fb is not None:
                shares = [_clip_shares(o, fb) for o in outcomes]
                entry["correction_limit_share"] = float(np.mean([s[0] for s in shares]))
            out["maps"][map_name][law] = entry
    out["wall_s"] = time.perf_counter() - t0
    return out


def treadmill_run(seed: int, control: str) -> dict[str, Any]:
    """setups.treadmill's run, open loop or closed loop with the chosen gains."""
    setup = LoopSetup(feedback=CHOSEN_GAINS[0] if control == "closed" else None)
    return {"control": control, **treadmill(seed, setup)}


def summarize(results: dict[str, list[dict[str, Any]]]) -> dict[str, Any]:
    """The headline figures, pooled over seeds (medians over every seed's trajectories)."""
    out: dict[str, Any] = {}
    a = results.get("air", [])
    if a:
        for map_name in ("babbling", "refined"):
            open_rmse = np.concatenate([r["maps"][map_name]["open"]["rmse_rad"] for r in a])
            for law in air_laws():
                rmse = np.concatenate([r["maps"][map_name][law]["rmse_rad"] for r in a])
                mse = np.concatenate([r["maps"][map_name][law]["mse_deg2"] for r in a])
                per_seed = [float(np.median(r["maps"][map_name][law]["rmse_rad"])) for r in a]
                out[f"air_{map_name}_{law}"] = {
                    "median_rmse_rad": float(np.median(rmse)),
                    "rmse_quartiles_rad": np.percentile(rmse, [25, 75]).tolist(),
                    "median_mse_deg2": float(np.median(mse)),
                    "per_seed_median_rmse_range_rad": [min(per_seed), max(per_seed)],
                    "ratio_to_open": float(np.median(rmse) / np.median(open_rmse)),
                    "share_better_than_open": float(np.mean(rmse < open_rmse)),
                }
        out["air_median_train_rmse_rad"] = float(np.median([x for r in a for x in r["train_rmse_rad"]]))
    t = results.get("treadmill", [])
    for control in ("open", "closed"):
        runs = [r for r in t if r["control"] == control]
        if not runs:
            continue
        crossed = [r for r in runs if r["crossed"]]
        out[f"treadmill_{control}"] = {
            "crossed": f"{len(crossed)}/{len(runs)}",
            "median_attempts_to_cross": float(np.median([r["attempts_to_cross"] for r in crossed]))
            if crossed
            else None,
            "attempts_to_cross_range": [
                min(r["attempts_to_cross"] for r in crossed),
                max(r["attempts_to_cross"] for r in crossed),
            ]
            if crossed
            else None,
            "median_best_reward_mm": float(np.median([r["best_reward_mm"] for r in runs])),
            "best_reward_range_mm": [
                float(min(r["best_reward_mm"] for r in runs)),
                float(max(r["best_reward_mm"] for r in runs)),
            ],
            "median_energy_per_attempt_j": float(np.median([e for r in runs for e in r["energies_j"]])),
            "median_tracking_rmse_rad": float(np.median([x for r in runs for x in r["tracking_rmse_rad"]])),
            "median_run_wall_s": float(np.median([r["wall_s"] for r in runs])),
        }
    return out


def plot(results: dict[str, list[dict[str, Any]]], out: Path) -> list[str]:
    """closed_loop_air.png (test RMSE per map and law) and closed_loop_treadmill.png; returns the names."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = []
    labels = {
        "open": "open\nloop",
        "follow_up": "follow-up\nP,I",
        "chosen": "chosen\n(V, I)",
        "chosen_delay4": "chosen\n51 ms",
        "chosen_delay8": "chosen\n103 ms",
        "follow_up_delay8": "follow-up\n103 ms",
    }
    if results.get("air"):
        fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
        for ax, map_name in zip(axes, ("babbling", "refined"), strict=True):
            data = [
                np.concatenate([r["maps"][map_name][law]["rmse_rad"] for r in results["air"]])
                for law in labels
            ]
            ax.boxplot(data, tick_labels=list(labels.values()), showfliers=False)
            ax.axhline(0.10, ls=":", color="k", label="goal 0.10 rad")
            ax.set(
                yscale="log",
                title=f"{'babbling-only' if map_name == 'babbling' else 'refined'} map, unseen trajectories",
            )
            ax.tick_params(axis="x", labelsize=8)
        axes[0].set_ylabel("tracking RMSE in the air (rad)")
        axes[0].legend(loc="lower left")
        fig.tight_layout()
        fig.savefig(out / "closed_loop_air.png", dpi=90)
        plt.close(fig)
        names.append("closed_loop_air.png")
    if results.get("treadmill"):
        fig, axes = plt.subplots(1, 3, figsize=(10, 3.6))
        runs = {c: [r for r in results["treadmill"] if r["control"] == c] for c in ("open", "closed")}
        for ax, (key, ylabel) in zip(
            axes,
            (
                ("best_reward_mm", "best reward per run (mm)"),
                ("energies_j", "energy per attempt (J)"),
                ("tracking_rmse_rad", "tracking RMSE per attempt (rad)"),
            ),
            strict=True,
        ):
            data = [
                [r[key] for r in rs] if key == "best_reward_mm" else [x for r in rs for x in r[key]]
                for rs in runs.values()
            ]
            ax.boxplot(data, tick_labels=["open loop", "closed loop"])
            ax.set(ylabel=ylabel)
        fig.suptitle("Treadmill learning runs, open vs closed loop (chosen gains)")
        fig.tight_layout()
        fig.savefig(out / "closed_loop_treadmill.png", dpi=90)
        plt.close(fig)
        names.append("closed_loop_treadmill.png")
    return names


def table(summary: dict[str, Any]) -> str:
    """The headline figures beside the follow-up's, as markdown."""
    rows = ["| quantity | simulated rig | follow-up (simulation) | goal |", "| --- | --- | --- | --- |"]

    def air_row(label: str, key: str, paper: str = "", goal: str = "") -> None:
        s = summary.get(key)
        if s is None:
            return
        q = s["rmse_quartiles_rad"]
        rows.append(
            f"| {label} | **{s['median_rmse_rad']:.3f} rad** ({q[0]:.3f}-{q[1]:.3f}); "
            f"{s['median_mse_deg2']:.0f} deg^2; x{s['ratio_to_open']:.2f} of open loop | {paper} | {goal} |"
        )

    for map_name, label in (("babbling", "babbling-only map"), ("refined", "refined map")):
        air_row(
            f"air, {label}: open loop", f"air_{map_name}_open", "0.373 rad" if map_name == "babbling" else ""
        )
        air_row(f"air, {label}: closed loop, follow-up's gains", f"air_{map_name}_follow_up", "0.099 rad")
        air_row(
            f"air, {label}: closed loop, chosen gains",
            f"air_{map_name}_chosen",
            goal="<= 0.10 rad and <= 1/3 of open loop",
        )
        air_row(f"air, {label}: chosen gains for 51 ms delay", f"air_{map_name}_chosen_delay4")
        air_row(f"air, {label}: chosen gains for 103 ms delay", f"air_{map_name}_chosen_delay8")
        air_row(
            f"air, {label}: follow-up's gains, 103 ms delay",
            f"air_{map_name}_follow_up_delay8",
            "0.305 rad (100 ms)",
        )
    for control in ("open", "closed"):
        s = summary.get(f"treadmill_{control}")
        if s is None:
            continue
        rng = s["attempts_to_cross_range"]
        rows.append(
            f"| treadmill, {control} loop: runs crossing; attempts to cross, median (range) | "
            f"**{s['crossed']}**; {s['median_attempts_to_cross']} ({rng[0]}-{rng[1]}) | | |"
            if rng
            else f"| treadmill, {control} loop: runs crossing | **{s['crossed']}** | | |"
        )
        br = s["best_reward_range_mm"]
        rows.append(
            f"| treadmill, {control} loop: best reward, median (range); energy per attempt, median | "
            f"**{s['median_best_reward_mm']:.0f} mm** ({br[0]:.0f}-{br[1]:.0f}); "
            f"{s['median_energy_per_attempt_j']:.1f} J | | |"
        )
        rows.append(
            f"| treadmill, {control} loop: tracking RMSE per attempt, median | "
            f"**{s['median_tracking_rmse_rad']:.3f} rad** | {'0.376' if control == 'open' else '0.131'} rad "
            "(walking with contact) | |"
        )
    return "\n".join(rows)


def main() -> None:
    """Run the experiments over the seeds and write the results."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=15)
    parser.add_argument("--workers", type=int, default=None, help="local Ray: CPUs to use (default: all)")
    parser.add_argument("--address", default=None, help="a Ray cluster (default: RAY_ADDRESS, else local)")
    parser.add_argument("--experiments", default="air,treadmill")
    parser.add_argument("--out", type=Path, default=Path("docs/results"))
    parser.add_argument("--sweep-stages", default="coarse,fine", help="coarse, fine or both")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    names = args.experiments.split(",")
    failures: list[JobFailure] = []

    def sweep(fn: Any, jobs: list[dict[str, Any]], desc: str) -> list[dict[str, Any]]:
        result = run_sweep(fn, jobs, desc=desc)
        failures.extend(result.failures)
        return result.rows

    results: dict[str, list[dict[str, Any]]] = {}
    wall_s: dict[str, float] = {}
    with ray_session(args.address, args.workers) as workers:
        if "sweep" in names:
            t0 = time.perf_counter()
            tasks = [
                {"seed": s, "delay_ticks": d, "stage": stage}
                for stage in args.sweep_stages.split(",")
                for d in SWEEP_DELAYS
                for s in range(args.seeds)
            ]
            done = sweep(_sweep_task, tasks, "sweep")
            wall = time.perf_counter() - t0
            rows = summarize_sweep(done)
            (args.out / "closed_loop_sweep.json").write_text(
                json.dumps(
                    _rounded({"summary": rows, "wall_s": wall, "knee_scale": KNEE_SCALE, "runs": done}),
                    indent=1,
                )
            )
            print(f"sweep: {args.seeds} seeds in {wall:.0f} s", flush=True)
            print(print_sweep(rows), flush=True)
        if "air" in names:
            t0 = time.perf_counter()
            results["air"] = sweep(air, [{"seed": s} for s in range(args.seeds)], "air")
            wall_s["air"] = time.perf_counter() - t0
            print(f"air: {args.seeds} seeds in {wall_s['air']:.0f} s", flush=True)
        if "treadmill" in names:
            t0 = time.perf_counter()
            tasks = [{"seed": s, "control": c} for s in range(args.seeds) for c in ("open", "closed")]
            results["treadmill"] = sweep(treadmill_run, tasks, "treadmill")
            wall_s["treadmill"] = time.perf_counter() - t0
            print(f"treadmill: {args.seeds} seeds x 2 in {wall_s['treadmill']:.0f} s", flush=True)
    for failure in failures:
        print(f"FAILED {failure.params}: {failure.error}", file=sys.stderr)
    if not results:
        return
    summary = summarize(results)
    summary["wall_s"] = {**wall_s, "total": sum(wall_s.values())}
    summary["workers"] = workers
    laws = {name: _describe(fb) for name, fb in air_laws().items()}
    (args.out / "closed_loop.json").write_text(
        json.dumps(
            _rounded(
                {
                    "summary": summary,
                    "follow_up_paper": FOLLOW_UP_PAPER,
                    "laws": laws,
                    "chosen_is_default": CHOSEN_GAINS[0] == FeedbackConfig(),
                    "runs": results,
                }
            ),
            indent=1,
        )
    )
    print("figures:", ", ".join(plot(results, args.out)))
    print(table(summary))
    if failures:
        sys.exit(1)


if __name__ == "__main__":
    main()
