"""Run identifiers and the layout of a run's directory under the bags root.

A run id is the UTC start time to the second and a short random suffix, `20261121T120000Z-ab12cd`, so
ids sort by time and two recorders started in the same second still get different ids. A run's
directory `<bags>/<run-id>/` is the rosbag2 bag itself (metadata.yaml, `<run-id>.mcap`), with the
report tool's outputs beside it.
"""

from __future__ import annotations

import re
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

RUN_ID_PATTERN = re.compile(r"^\d{8}T\d{6}Z-[0-9a-f]{6}$")
SUMMARY_JSON = "summary.json"
REPORT_DIR = "report"
METADATA_YAML = "metadata.yaml"


def new_run_id(now: datetime, rng: np.random.Generator) -> str:
    """A run id for a run started at `now`.

    Args:
        now: start time; must be timezone-aware (it is converted to UTC).
        rng: source of the 24-bit random suffix (6 hex digits).

    Raises:
        ValueError: `now` is naive.
    """
    if now.tzinfo is None:
        raise ValueError("new_run_id needs a timezone-aware datetime")
    stamp = now.astimezone(timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    return f"{stamp}-{int(rng.integers(0, 1 << 24)):06x}"


def is_run_id(text: str) -> bool:
    """Whether `text` has the form of a run id."""
    return RUN_ID_PATTERN.match(text) is not None


def is_safe_name(text: str) -> bool:
    """Whether `text` can name a run directory: letters, digits, '_', '-', '.', not starting with '.'."""
    return re.match(r"^[A-Za-z0-9_-][A-Za-z0-9_.-]*$", text) is not None


def summary_path(run_dir: Path) -> Path:
    """Where the report tool writes a run's summary (JSON)."""
    return run_dir / SUMMARY_JSON


def report_dir(run_dir: Path) -> Path:
    """Where the report tool writes a run's figures (PNG) and summary table (markdown)."""
    return run_dir / REPORT_DIR
