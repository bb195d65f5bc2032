"""A run's summary (JSON and markdown) and figures, from its bag alone; the `g2p-report` command.

    g2p-report bags/<run> [--attempt K] [--out DIR]

Writes `bags/<run>/summary.json` and `bags/<run>/report/` (summary.md and the figures, PNG). A bag that
cannot be read gives one line on stderr and exit status 2. Needs no ROS.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path

from g2p.bags import plots
from g2p.bags.dataset import AttemptData, RunData, load_run
from g2p.bags.errors import BagError
from g2p.bags.runs import report_dir, summary_path
from g2p.bags.summary import find_joint_limits, find_threshold, summarize, summary_markdown
from g2p.rig import DEFAULT_NAMESPACE

FIGURES = (
    "fig4a_reward.png",
    "fig4b_reward_energy.png",
    "fig5a_tracking.png",
    "fig5b_tracking_mse.png",
    "fig6_angle_distribution.png",
)


@dataclass(frozen=True)
class ReportResult:
    """Where a report was written.

    Attributes:
        summary_json: the summary (JSON).
        summary_markdown: the summary table (markdown).
        figures: the figures written.
        skipped: figures not drawn for lack of data, with the reason.
    """

    summary_json: Path
    summary_markdown: Path
    figures: list[Path]
    skipped: dict[str, str]


def write_report(
    bag: Path | str,
    attempt: int | None = None,
    rig_namespace: str = DEFAULT_NAMESPACE,
    out_dir: Path | None = None,
) -> ReportResult:
    """Write `summary.json` beside the bag and `report/*.png` plus `report/summary.md`.

    Args:
        bag: the bag directory (the run directory).
        attempt: the attempt shown in Fig 5a and 6; None for the last attempt with a desired trajectory,
            else the best attempt.
        rig_namespace: namespace of the rig topics.
        out_dir: write there instead of into the run directory (summary.json and report/ inside it).

    Raises:
        BagReadError: the bag cannot be read.
        BagError: the attempt does not exist, or the outputs cannot be written.
    """
    run = load_run(bag, rig_namespace)
    root = Path(out_dir) if out_dir is not None else Path(bag)
    figures_dir = report_dir(root)
    summary = summarize(run)
    threshold, _ = find_threshold(run)
    limits, _ = find_joint_limits(run)
    shown = _shown_attempt(run, attempt)
    drawn = {
        FIGURES[0]: (
            plots.reward_per_attempt(run, threshold, figures_dir / FIGURES[0]),
            "no attempt rewards",
        ),
        FIGURES[1]: (plots.reward_vs_energy(run, threshold, figures_dir / FIGURES[1]), "no attempt energies"),
        FIGURES[2]: (plots.tracking(shown, figures_dir / FIGURES[2]) if shown else None, "no attempt ticks"),
        FIGURES[3]: (plots.tracking_mse(run, figures_dir / FIGURES[3]), "no tracking MSE reported"),
        FIGURES[4]: (
            plots.angle_distribution(run, shown, limits, figures_dir / FIGURES[4]),
            "no babbling ticks",
        ),
    }
    figures = [p for p, _ in drawn.values() if p is not None]
    skipped = {name: reason for name, (p, reason) in drawn.items() if p is None}
    summary["figures"] = {
        name: ("report/" + name if name not in skipped else f"skipped: {skipped[name]}") for name in FIGURES
    }
    summary["report_attempt"] = shown.attempt if shown is not None else None
    try:
        figures_dir.mkdir(parents=True, exist_ok=True)
        json_path = summary_path(root)
        json_path.write_text(json.dumps(summary, indent=2, allow_nan=False) + "\n", encoding="utf-8")
        md_path = figures_dir / "summary.md"
        md_path.write_text(summary_markdown(summary), encoding="utf-8")
    except OSError as err:
        raise BagError(f"cannot write the report: {err}", root) from err
    return ReportResult(json_path, md_path, figures, skipped)


def _shown_attempt(run: RunData, attempt: int | None) -> AttemptData | None:
    if attempt is not None:
        found = [a for a in run.attempts if a.attempt == attempt]
        if not found:
            raise BagError(
                f"attempt {attempt} is not in the run (attempts: "
                f"{', '.join(str(a.attempt) for a in run.attempts) or 'none'})",
                run.bag,
            )
        return found[-1]
    with_desired = [a for a in run.attempts if a.desired_position_rad is not None and len(a.recording)]
    if with_desired:
        return with_desired[-1]
    rewarded = [a for a in run.attempts if math.isfinite(a.reward_mm) and len(a.recording)]
    if rewarded:
        return max(rewarded, key=lambda a: a.reward_mm)
    return next((a for a in reversed(run.attempts) if len(a.recording)), None)


def main(args: list[str] | None = None) -> None:
    """Entry point of `g2p-report`: write the report of one run; exit 2 when the bag cannot be read."""
    parser = argparse.ArgumentParser(
        prog="g2p-report",
        description="Summary (JSON, markdown) and figures (PNG) of a recorded run, from its bag.",
    )
    parser.add_argument("bag", type=Path, help="the run's bag directory (bags/<run-id>)")
    parser.add_argument(
        "--attempt",
        type=int,
        default=None,
        help="attempt shown in the tracking and angle-distribution figures (default: the last "
        "with a desired trajectory, else the best)",
    )
    parser.add_argument("--namespace", default=DEFAULT_NAMESPACE, help="namespace of the rig topics")
    parser.add_argument("--out", type=Path, default=None, help="write here instead of into the bag directory")
    ns = parser.parse_args(sys.argv[1:] if args is None else args)
    try:
        result = write_report(ns.bag, attempt=ns.attempt, rig_namespace=ns.namespace, out_dir=ns.out)
    except BagError as err:
        print(f"g2p-report: error: {err}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        sys.exit(130)
    print(f"summary: {result.summary_json}")
    print(f"table:   {result.summary_markdown}")
    for figure in result.figures:
        print(f"figure:  {figure}")
    for name, reason in result.skipped.items():
        print(f"skipped: {name} ({reason})")


if __name__ == "__main__":
    main()
