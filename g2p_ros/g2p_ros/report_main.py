"""`ros2 run g2p_ros report bags/<run>`: a run's summary and figures from its bag alone (no ROS needed).

Writes `bags/<run>/summary.json` and `bags/<run>/report/` (summary.md and the figures, PNG). A bag
that cannot be read gives one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from g2p.bags import BagError, write_report
from g2p.bags.dataset import DEFAULT_RIG_NAMESPACE


def main(args: list[str] | None = None) -> None:
    """Write the report of one run; exit 2 with one line on stderr when the bag cannot be read."""
    parser = argparse.ArgumentParser(
        prog="report",
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
    parser.add_argument("--namespace", default=DEFAULT_RIG_NAMESPACE, help="namespace of the rig topics")
    parser.add_argument("--out", type=Path, default=None, help="write here instead of into the bag directory")
    ns = parser.parse_args(sys.argv[1:] if args is None else args)
    try:
        result = write_report(ns.bag, attempt=ns.attempt, rig_namespace=ns.namespace, out_dir=ns.out)
    except BagError as err:
        print(f"report: error: {err}", file=sys.stderr)
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
