"""G2P against PPO and SAC (Stable-Baselines3) on the same simulated rig, measured in rig time.

    scripts/with-env python benchmarks/bench_rl.py --seeds 5 --budget-h ppo=2 --budget-h sac=1 \
        --out docs/results/rl

Each job (g2p.baselines.run_method) is one method and one seed on a fresh simulated rig; the jobs run on
the sweep runner (g2p.sweep, Ray: local by default, a cluster with --address or RAY_ADDRESS). Writes into
--out: results.csv (one row per method x seed), summary.json (medians per method), best_reward.png (best
reward so far against rig time, median and range over the seeds), and prints a markdown table.
"""

from __future__ import annotations

import argparse
import json
import math
import warnings
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from g2p.baselines import MARKS_S, METHODS, THRESHOLD_MM, run_method
from g2p.sweep import run_sweep

COLOURS = {"g2p": "tab:green", "ppo": "tab:blue", "sac": "tab:orange", "random": "tab:grey"}


def parse_budget(text: str) -> tuple[str, float]:
    """'ppo=2' -> ('ppo', 7200.0): a method's budget of rig time in hours."""
    method, sep, hours = text.partition("=")
    if not sep or method not in METHODS[1:]:
        raise argparse.ArgumentTypeError(f"expected ppo=, sac= or random=HOURS, got {text!r}")
    return method, float(hours) * 3600.0


def _median(values: list[Any]) -> float | None:
    v = [x for x in values if x is not None and not (isinstance(x, float) and math.isnan(x))]
    return float(np.median(v)) if v else None


def first_time_at(times: list[float], rewards: list[float], level_mm: float) -> float | None:
    """Rig time at the end of the first episode whose reward exceeds `level_mm` (s); None if none did."""
    return next((t for t, r in zip(times, rewards, strict=True) if r > level_mm), None)


def summarize(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Medians per method, and how much less rig time G2P needs than the better baseline."""
    by_method: dict[str, list[dict[str, Any]]] = {}
    for row in rows:
        by_method.setdefault(row["method"], []).append(row)
    g2p_best = _median([r["best_mm"] for r in by_method.get("g2p", [])])
    summary: dict[str, Any] = {"threshold_mm": THRESHOLD_MM, "g2p_median_best_mm": g2p_best, "methods": {}}
    for method, runs in by_method.items():
        to_g2p_best = [
            first_time_at(r["curve_rig_time_s"], r["curve_reward_mm"], g2p_best) if g2p_best else None
            for r in runs
        ]
        summary["methods"][method] = {
            "seeds": len(runs),
            "crossed": sum(r["rig_time_to_threshold_s"] is not None for r in runs),
            "rig_time_to_threshold_s": _median([r["rig_time_to_threshold_s"] for r in runs]),
            "reached_g2p_best": sum(t is not None for t in to_g2p_best),
            "rig_time_to_g2p_best_s": _median(to_g2p_best),
            "best_mm_10min": _median([r["best_mm_10min"] for r in runs]),
            "best_mm_1h": _median([r["best_mm_1h"] for r in runs]),
            "best_mm": _median([r["best_mm"] for r in runs]),
            "rig_time_s": _median([r["rig_time_s"] for r in runs]),
            "wall_s": _median([r["wall_s"] for r in runs]),
            "cpu_s": _median([r["cpu_s"] for r in runs]),
        }
    methods = summary["methods"]
    g2p_t = methods.get("g2p", {}).get("rig_time_to_threshold_s")
    baseline_t = [methods[m]["rig_time_to_threshold_s"] for m in ("ppo", "sac") if m in methods]
    baseline_t = [t for t in baseline_t if t is not None]
    summary["threshold_speedup"] = min(baseline_t) / g2p_t if g2p_t and baseline_t else None
    return summary


def plot(rows: list[dict[str, Any]], out: Path) -> None:
    """Best reward so far against rig time (log scale): median over seeds, and their range."""
    grid = np.logspace(1, math.log10(max(r["rig_time_s"] for r in rows) * 1.05), 300)
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for method in METHODS:
        runs = [r for r in rows if r["method"] == method]
        if not runs:
            continue
        curves = []
        for r in runs:
            t = np.asarray(r["curve_rig_time_s"])
            best = np.maximum.accumulate(np.asarray(r["curve_reward_mm"]))
            k = np.searchsorted(t, grid, side="right") - 1
            curves.append(np.where((k >= 0) & (grid <= t[-1]), best[np.clip(k, 0, None)], np.nan))
        c = np.array(curves)
        with warnings.catch_warnings():  # grid points before a seed's first episode are all-NaN columns
            warnings.simplefilter("ignore", RuntimeWarning)
            med, low, high = np.nanmedian(c, 0), np.nanmin(c, 0), np.nanmax(c, 0)
        ax.plot(grid, med, color=COLOURS[method], label=f"{method.upper()} ({len(runs)} seeds)")
        ax.fill_between(grid, low, high, color=COLOURS[method], alpha=0.2, linewidth=0)
    ax.axhline(THRESHOLD_MM, color="grey", linestyle="--", linewidth=0.8, label=f"{THRESHOLD_MM:g} mm")
    for mark in MARKS_S:
        ax.axvline(mark, color="grey", linestyle=":", linewidth=0.8)
    ax.set_xscale("log")
    ax.set_xlabel("rig time (s, log scale; G2P's babbling included)")
    ax.set_ylabel("best 20-cycle reward so far (mm)")
    ax.set_title("G2P against model-free RL on the simulated rig")
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def markdown(summary: dict[str, Any]) -> str:
    """The summary as a markdown table."""

    def fmt(x: float | None, unit: str = "") -> str:
        return "never" if x is None else f"{x:.0f}{unit}"

    lines = [
        "| method | crossed 64 mm | rig time to 64 mm | best by 10 min | best by 1 h | best | rig time to "
        f"G2P's best ({fmt(summary['g2p_median_best_mm'])} mm) | rig time used | wall | CPU |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for method, m in summary["methods"].items():
        lines.append(
            f"| {method.upper()} | {m['crossed']}/{m['seeds']} | {fmt(m['rig_time_to_threshold_s'], ' s')} | "
            f"{fmt(m['best_mm_10min'], ' mm')} | {fmt(m['best_mm_1h'], ' mm')} | "
            f"{fmt(m['best_mm'], ' mm')} | "
            f"{fmt(m['rig_time_to_g2p_best_s'], ' s')} ({m['reached_g2p_best']}/{m['seeds']}) | "
            f"{fmt(m['rig_time_s'], ' s')} | {fmt(m['wall_s'], ' s')} | {fmt(m['cpu_s'], ' s')} |"
        )
    return "\n".join(lines)


def main() -> None:
    """Run the comparison and write its table, summary and plot."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--methods", default=",".join(METHODS))
    parser.add_argument(
        "--budget-h", type=parse_budget, action="append", default=[], help="METHOD=HOURS of rig time"
    )
    parser.add_argument("--frame-skip", type=int, default=4, help="ticks per RL action (4: 19.5 Hz)")
    parser.add_argument("--calibration", default="", help='the simulated rig: "" (default) or "paper"')
    parser.add_argument("--workers", type=int, default=None, help="local Ray CPUs (default: all)")
    parser.add_argument("--address", default=None, help="a Ray cluster (default: RAY_ADDRESS, else local)")
    parser.add_argument("--out", type=Path, default=Path("docs/results/rl"))
    args = parser.parse_args()
    budgets = {"ppo": 7200.0, "sac": 3600.0, "random": 3600.0, **dict(args.budget_h)}
    methods = [m for m in args.methods.split(",") if m]
    unknown = sorted(set(methods) - set(METHODS))
    if unknown:
        parser.error(f"unknown methods {unknown}; choose from {list(METHODS)}")
    # The longest jobs first, so that the workers finish together.
    order = sorted(methods, key=lambda m: -budgets.get(m, 0.0) * (4.0 if m == "sac" else 1.0))
    jobs = [
        {
            "method": m,
            "seed": seed,
            "budget_s": budgets.get(m, 0.0),
            "frame_skip": args.frame_skip,
            "calibration": args.calibration,
        }
        for m in order
        for seed in range(args.seeds)
    ]
    result = run_sweep(run_method, jobs, address=args.address, workers=args.workers, desc="bench_rl")
    args.out.mkdir(parents=True, exist_ok=True)
    result.write_csv(args.out / "results.csv")
    summary = summarize(result.rows)
    summary["jobs"] = len(jobs)
    summary["failures"] = [{"params": f.params, "error": f.error} for f in result.failures]
    summary["sweep_wall_s"] = result.wall_s
    summary["budgets_s"] = {m: budgets[m] for m in methods if m in budgets}
    summary["frame_skip"] = args.frame_skip
    summary["calibration"] = args.calibration
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    if result.rows:
        plot(result.rows, args.out / "best_reward.png")
    print(markdown(summary))
    if summary["threshold_speedup"] is not None:
        print(
            f"\nrig time to {THRESHOLD_MM:g} mm, better baseline / G2P (medians): "
            f"{summary['threshold_speedup']:.3g} (goal: >= 50)"
        )
    for f in result.failures:
        print(f"FAILED {f.params}: {f.error}")


if __name__ == "__main__":
    main()
