"""G2P against model-free RL on the same simulated rig, run as it runs, measured in rig time.

    scripts/with-env python benchmarks/bench_rl.py --calibration paper --threshold-mm 76.3 --seeds 10 \
        --methods g2p,random,ppo --budget-min 60 --out docs/results/rl_paper/main
    scripts/with-env python benchmarks/bench_rl.py --summarize docs/results/rl_paper/*/ \
        --out docs/results/rl_paper

Each job (g2p.rl.baselines.run_method) is one method and one seed on a fresh simulated rig; the jobs run on
the sweep runner (g2p.rl.sweep, Ray: local by default, a cluster with --address or RAY_ADDRESS). A run writes
into --out: results.csv (one row per job), summary.json and a markdown table. --summarize reads the
results.csv of several runs (methods at different budgets, rates or babbling lengths; a seed run at
several budgets counts once, at its longest) and writes their joint summary.json, table.md and
best_reward.png into --out; --marks-min sets the table's marks (the best reward by each, from every
run's curve).

A variant's label is its method, then "@78Hz" for an RL method at frame skip 1, and for G2P "babbling N s",
"cycle N ticks" and "refined on last N attempts" when they differ from the paper's 5 min, 80 ticks and
every attempt. Every figure is a median over
seeds with the bootstrap 95 % interval of the median (10,000 resamples); a seed that never crossed the
threshold counts as never (infinite time), so the median is "never" when half of them did not; "none" is
a best reward before any episode or attempt ended.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import warnings
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from g2p.rl.baselines import MARKS_S, METHODS, RL_METHODS, best_by, chance_threshold_mm, run_method
from g2p.rl.sweep import run_sweep
from g2p.sim import MujocoLegConfig

COLOURS = {
    "g2p": "tab:green",
    "g2p_ppo": "tab:olive",
    "ppo": "tab:blue",
    "sac": "tab:orange",
    "tqc": "tab:red",
    "random": "tab:grey",
}
BOOTSTRAP = 10_000


def label(row: dict[str, Any]) -> str:
    """The variant a row belongs to: its method, its rate (RL at 78 Hz), G2P's babbling, cycle, refinement."""
    name = str(row["method"])
    if name in RL_METHODS and int(row["frame_skip"]) == 1:
        name += "@78Hz"
    if name.startswith("g2p") and float(row.get("babbling_s") or 0):
        name += f" babbling {float(row['babbling_s']):g} s"
    if name.startswith("g2p") and float(row.get("cycle_ticks") or 0):
        name += f" cycle {float(row['cycle_ticks']):g} ticks"
    if name.startswith("g2p") and float(row.get("recent_attempts") or 0):
        name += f" refined on last {float(row['recent_attempts']):g} attempts"
    return name


def longest_runs(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per variant and seed: a seed run at several budgets counts once, at its longest.

    A run is deterministic in its seed, so a longer run's curve holds the shorter one's marks, and its
    held-out figures are those of the policy at the longest budget.
    """
    longest: dict[tuple[str, int], dict[str, Any]] = {}
    for row in rows:
        key = (label(row), int(row["seed"]))
        if key not in longest or float(row["budget_s"]) > float(longest[key]["budget_s"]):
            longest[key] = row
    return list(longest.values())


def median_ci(
    values: list[float | None], missing: float = math.inf, seed: int = 0
) -> tuple[float, float, float] | None:
    """Median and bootstrap 95 % interval of the median; None counts as `missing`. None if no values.

    A time that never came counts as +inf ("never"); a best reward before any episode ended as -inf
    ("none").
    """
    if not values:
        return None
    v = np.array([missing if x is None else float(x) for x in values])
    rng = np.random.default_rng(seed)
    medians = np.median(rng.choice(v, size=(BOOTSTRAP, len(v))), axis=1)
    low, high = np.quantile(medians, [0.025, 0.975], method="inverted_cdf")
    return float(np.median(v)), float(low), float(high)


def summarize(
    rows: list[dict[str, Any]], threshold_mm: float, marks_s: tuple[float, ...] = MARKS_S
) -> dict[str, Any]:
    """Per variant: seeds, crossings, rig time to the threshold, best by each mark (s), held-out figures."""
    variants: dict[str, list[dict[str, Any]]] = {}
    for row in rows:
        variants.setdefault(label(row), []).append(row)
    summary: dict[str, Any] = {"threshold_mm": threshold_mm, "marks_s": list(marks_s), "variants": {}}
    for name, runs in variants.items():
        budget_s = min(float(r["budget_s"]) for r in runs)
        entry: dict[str, Any] = {
            "seeds": len(runs),
            "budget_s": budget_s,
            "crossed": sum(r["rig_time_to_threshold_s"] is not None for r in runs),
            "rig_time_to_threshold_s": median_ci([r["rig_time_to_threshold_s"] for r in runs]),
        }
        for mark in marks_s:
            # A mark beyond the budget is not reported (the run did not get that far).
            best = [best_by(r["curve_rig_time_s"], r["curve_reward_mm"], mark) for r in runs]
            entry[f"best_mm_{mark / 60:g}min"] = (
                median_ci(best, -math.inf) if mark <= budget_s * 1.001 else None
            )
        entry["eval_mm"] = median_ci([r["eval_mm"] for r in runs])
        entry["eval_j_per_mm"] = median_ci([r["eval_j_per_mm"] for r in runs])
        paper_stop = [r.get("paper_stop_s") for r in runs if r.get("paper_stop_s") is not None]
        entry["paper_stop_s"] = float(np.median(np.array(paper_stop, dtype=float))) if paper_stop else None
        entry["faults"] = int(sum(r.get("faults") or 0 for r in runs))  # G2P's attempts a limit tripped
        entry["wall_s"] = float(np.median([r["wall_s"] for r in runs]))
        entry["cpu_s"] = float(np.median([r["cpu_s"] for r in runs]))
        summary["variants"][name] = entry
    return summary


def markdown(summary: dict[str, Any]) -> str:
    """The summary as a markdown table: median [95 % interval] per variant."""

    def fmt(m: tuple[float, float, float] | None, unit: str = "", digits: int = 0) -> str:
        if m is None:
            return "-"
        parts = [("never" if x > 0 else "none") if math.isinf(x) else f"{x:.{digits}f}" for x in m]
        return f"{parts[0]}{'' if math.isinf(m[0]) else unit} [{parts[1]}, {parts[2]}]"

    marks = [f"{m / 60:g} min" for m in summary["marks_s"]]
    lines = [
        f"| variant | seeds | crossed {summary['threshold_mm']:g} mm | rig time to it | "
        + " | ".join(f"best by {m}" for m in marks)
        + " | held-out (mm) | held-out (J/mm) | wall, CPU per run |",
        "| --- " * (7 + len(marks)) + "|",
    ]
    for name, v in summary["variants"].items():
        best = [fmt(v[f"best_mm_{m / 60:g}min"], " mm") for m in summary["marks_s"]]
        lines.append(
            f"| {name} | {v['seeds']} | {v['crossed']}/{v['seeds']} | "
            f"{fmt(v['rig_time_to_threshold_s'], ' s')} | {' | '.join(best)} | {fmt(v['eval_mm'], ' mm')} | "
            f"{fmt(v['eval_j_per_mm'], '', 2)} | {v['wall_s']:.0f} s, {v['cpu_s']:.0f} s |"
        )
    return "\n".join(lines)


def plot(
    rows: list[dict[str, Any]], threshold_mm: float, title: str, out: Path, marks_s: tuple[float, ...]
) -> None:
    """Best reward so far against rig time (log scale): median over seeds, and its bootstrap interval."""
    grid = np.logspace(1, math.log10(max(float(r["rig_time_s"]) for r in rows) * 1.05), 200)
    variants: dict[str, list[dict[str, Any]]] = {}
    for row in rows:
        variants.setdefault(label(row), []).append(row)
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    styles = ["-", "--", ":", "-."]
    seen: dict[str, int] = {}
    for name, runs in variants.items():
        curves = []
        for r in runs:
            t = np.asarray(r["curve_rig_time_s"])
            best = np.maximum.accumulate(np.asarray(r["curve_reward_mm"]))
            k = np.searchsorted(t, grid, side="right") - 1
            curves.append(np.where((k >= 0) & (grid <= t[-1]), best[np.clip(k, 0, None)], np.nan))
        c = np.array(curves)
        rng = np.random.default_rng(0)
        boot = c[rng.integers(0, len(c), size=(1000, len(c)))]
        with warnings.catch_warnings():  # grid points before a seed's first episode are all-NaN columns
            warnings.simplefilter("ignore", RuntimeWarning)
            med = np.nanmedian(c, 0)
            low, high = np.nanquantile(np.nanmedian(boot, 1), [0.025, 0.975], axis=0)
        method = str(runs[0]["method"])
        style = styles[seen.get(method, 0) % len(styles)]
        seen[method] = seen.get(method, 0) + 1
        colour = COLOURS.get(method, "black")
        ax.plot(grid, med, color=colour, linestyle=style, label=f"{name} ({len(runs)} seeds)")
        ax.fill_between(grid, low, high, color=colour, alpha=0.15, linewidth=0)
    ax.axhline(
        threshold_mm, color="grey", linestyle="--", linewidth=0.8, label=f"threshold {threshold_mm:g} mm"
    )
    for mark in marks_s:
        ax.axvline(mark, color="grey", linestyle=":", linewidth=0.8)
    ax.set_xscale("log")
    ax.set_xlabel("rig time (s, log scale; babbling and resets included)")
    ax.set_ylabel("best 20-cycle reward so far (mm)")
    ax.set_title(title)
    ax.legend(loc="upper left", fontsize=7)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def _cell(text: str) -> Any:
    if text == "":
        return None
    if text[0] in "[{":
        return json.loads(text)
    try:
        return float(text)
    except ValueError:
        return text


def read_rows(path: Path) -> list[dict[str, Any]]:
    """The rows of a results.csv as written by SweepResult.write_csv (JSON cells parsed, numbers floats)."""
    with path.open(newline="") as f:
        return [{k: _cell(v) for k, v in row.items()} for row in csv.DictReader(f)]


def write_summary(
    rows: list[dict[str, Any]], threshold_mm: float, calibration: str, out: Path, marks_s: tuple[float, ...]
) -> None:
    """summary.json, table.md and best_reward.png of `rows` into `out`; print the table."""
    summary = summarize(rows, threshold_mm, marks_s)
    summary["calibration"] = calibration
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    table = markdown(summary)
    (out / "table.md").write_text(table + "\n")
    rig = "sim_paper" if calibration == "paper" else calibration or "the default rig"
    plot(rows, threshold_mm, f"Best reward so far on {rig}, run as it runs", out / "best_reward.png", marks_s)
    print(table)


def main() -> None:
    """Run the comparison (or summarize runs) and write its table, summary and plot."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--methods", default=",".join(METHODS))
    parser.add_argument("--budget-min", type=float, default=60.0, help="rig time per run (min)")
    parser.add_argument(
        "--frame-skip", type=int, default=4, help="ticks per RL action (4: 19.5 Hz, 1: 78 Hz)"
    )
    parser.add_argument("--babbling-s", type=float, default=0.0, help="G2P's babbling (s; 0: the paper's)")
    parser.add_argument("--cycle-ticks", type=int, default=0, help="G2P's cycle (ticks; 0: the paper's 80)")
    parser.add_argument(
        "--recent-attempts",
        type=int,
        default=0,
        help="G2P refines on babbling and this many last attempts (0: every attempt, the paper's)",
    )
    parser.add_argument("--calibration", default="", help='the simulated rig: "" (default) or "paper"')
    parser.add_argument(
        "--threshold-mm",
        type=float,
        default=None,
        help="default: chance_threshold_mm of the rig (about 1 min)",
    )
    parser.add_argument("--workers", type=int, default=None, help="local Ray CPUs (default: all)")
    parser.add_argument("--address", default=None, help="a Ray cluster (default: RAY_ADDRESS, else local)")
    parser.add_argument("--summarize", type=Path, nargs="+", help="runs' --out directories to summarize")
    parser.add_argument("--marks-min", default="2,10,30,60", help="the table's marks of rig time (min)")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    marks_s = tuple(float(m) * 60.0 for m in args.marks_min.split(","))
    if args.summarize:
        rows = longest_runs([row for d in args.summarize for row in read_rows(d / "results.csv")])
        thresholds = {float(r["threshold_mm"]) for r in rows}
        if len(thresholds) != 1:
            parser.error(f"the runs counted to different thresholds: {sorted(thresholds)}")
        write_summary(rows, thresholds.pop(), str(rows[0]["calibration"] or ""), args.out, marks_s)
        return
    threshold = args.threshold_mm
    if threshold is None:
        threshold = round(chance_threshold_mm(MujocoLegConfig(seed=0, calibration=args.calibration)), 1)
    methods = [m for m in args.methods.split(",") if m]
    unknown = sorted(set(methods) - set(METHODS))
    if unknown:
        parser.error(f"unknown methods {unknown}; choose from {list(METHODS)}")
    jobs = [
        {
            "method": m,
            "seed": seed,
            "budget_s": args.budget_min * 60.0,
            "frame_skip": args.frame_skip,
            "calibration": args.calibration,
            "threshold_mm": threshold,
            "babbling_s": args.babbling_s,
            "cycle_ticks": args.cycle_ticks,
            "recent_attempts": args.recent_attempts,
        }
        for m in methods
        for seed in range(args.first_seed, args.first_seed + args.seeds)
    ]
    result = run_sweep(run_method, jobs, address=args.address, workers=args.workers, desc="bench_rl")
    args.out.mkdir(parents=True, exist_ok=True)
    result.write_csv(args.out / "results.csv")
    summary = summarize(read_rows(args.out / "results.csv"), threshold, marks_s) if result.rows else {}
    summary["sweep_wall_s"] = result.wall_s
    summary["failures"] = [{"params": f.params, "error": f.error} for f in result.failures]
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    if result.rows:
        print(markdown(summary))
    print(f"sweep: {len(jobs)} jobs in {result.wall_s:.0f} s")
    for f in result.failures:
        print(f"FAILED {f.params}: {f.error}")
    if result.failures:
        raise SystemExit(1)


if __name__ == "__main__":
    main()
