"""The numbers of a recorded run: per-attempt results, search progress, babbling coverage, map quality.

Pure functions of a `RunData`; the result is JSON-ready (NaN becomes null) and renders as tables
(markdown here; HTML in the report's index page).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from g2p.bags.dataset import RecordedAttempt, RunData
from g2p.bags.events import FloatArray
from g2p.learning.run_events import Event
from g2p.rig.envelope import stop_entry_speeds

# G2P_FACTS.md: exploration stops when an attempt's belt travel exceeds 64 mm.
PAPER_THRESHOLD_MM = 64.0
# Fig 6: a sample is near a limit when within 5% of the joint's range from it.
NEAR_LIMIT_BAND = 0.05


def find_threshold(run: RunData) -> tuple[float, str]:
    """The reward threshold (mm) and where it came from.

    Looked up in order: a "threshold_mm" field anywhere in the last run_start event's detail (the
    learner puts its search settings there); a recorded node configuration holding one; the paper's 64 mm.
    """
    for event in reversed(run.events):
        value = _find_key(event.detail, "threshold_mm") if event.event == Event.RUN_START else None
        if isinstance(value, int | float) and _is_number(value):
            return float(value), "run_start event"
    for topic, config in sorted(run.configs.items()):
        value = _find_key(config, "threshold_mm")
        if isinstance(value, int | float) and _is_number(value):
            return float(value), topic
    return PAPER_THRESHOLD_MM, "paper default"


def find_joint_limits(run: RunData) -> tuple[FloatArray | None, str]:
    """Joint limits, shape (2, 2) as [[low, high] per joint] (rad), and where they came from.

    Looked up in order: a "joint_limits_rad" field in the last run_start event's detail; a recorded
    node configuration holding one; the range babbling covered (or every tick's range without babbling).
    """
    for event in reversed(run.events):
        limits = (
            _limits(_find_key(event.detail, "joint_limits_rad")) if event.event == Event.RUN_START else None
        )
        if limits is not None:
            return limits, "run_start event"
    for topic, config in sorted(run.configs.items()):
        limits = _limits(_find_key(config, "joint_limits_rad"))
        if limits is not None:
            return limits, topic
    for name, recording in (("babbling range", run.babbling), ("recorded range", run.ticks.recording)):
        if len(recording):
            q = recording.position_rad
            limits = _limits(np.stack([q.min(axis=0), q.max(axis=0)], axis=1))
            if limits is not None:
                return limits, name
    return None, "no joint moved over a range"


def near_limit_fraction(
    position_rad: FloatArray, limits_rad: FloatArray, band: float = NEAR_LIMIT_BAND
) -> float:
    """Fraction of samples within `band` of a joint's range from one of its limits, on any joint.

    Args:
        position_rad: joint angles, shape (N, 2).
        limits_rad: [[low, high] per joint], shape (2, 2).
        band: width of the band near each limit, as a fraction of the joint's range.

    Returns:
        The fraction in [0, 1]; NaN for no samples.
    """
    if len(position_rad) == 0:
        return float("nan")
    low, high = limits_rad[:, 0], limits_rad[:, 1]
    margin = band * (high - low)
    near = (position_rad <= low + margin) | (position_rad >= high - margin)
    return float(np.mean(np.any(near, axis=1)))


def best_so_far(rewards: Iterable[float]) -> list[float]:
    """Running maximum of rewards, ignoring NaN (NaN until the first finite reward)."""
    best, out = float("nan"), []
    for r in rewards:
        if math.isfinite(r) and not (best >= r):
            best = r
        out.append(best)
    return out


def summarize(run: RunData) -> dict[str, Any]:
    """The run's summary as a JSON-ready dict (see docs/BAGS.md for each field)."""
    threshold, threshold_source = find_threshold(run)
    limits, limits_source = find_joint_limits(run)
    attempts = run.attempts
    rewards = [a.reward_mm for a in attempts]
    best = best_so_far(rewards)
    crossing = next((a.attempt for a in attempts if a.reward_mm > threshold), None)
    exploitation = [a for a in attempts if a.phase == "exploitation"]
    best_reward = max((r for r in rewards if math.isfinite(r)), default=float("nan"))
    best_attempt = next((a for a in attempts if a.reward_mm == best_reward), None)
    before_exploitation = [
        a.reward_mm for a in attempts if a.phase != "exploitation" and a.phase != "tracking"
    ]
    best_before = max((r for r in before_exploitation if math.isfinite(r)), default=float("nan"))
    summary: dict[str, Any] = {
        "run_id": run.run_id,
        "bag": str(run.bag),
        "duration_s": run.duration_s,
        "messages": dict(sorted(run.topic_counts.items())),
        "ticks": len(run.ticks.recording),
        "incomplete_ticks": run.ticks.incomplete,
        "threshold_mm": threshold,
        "threshold_source": threshold_source,
        "joint_limits_rad": limits.tolist() if limits is not None else None,
        "joint_limits_source": limits_source,
        "babbling": _segment_summary(run.babbling.t_s, run.babbling.position_rad, limits),
        "attempt_count": len(attempts),
        "exploration_attempts": sum(a.phase == "exploration" for a in attempts),
        "exploitation_attempts": len(exploitation),
        "attempts_to_threshold": crossing,
        "best_reward_mm": best_reward,
        "best_attempt": best_attempt.attempt if best_attempt is not None else None,
        "best_features": best_attempt.start.features.tolist() if best_attempt is not None else None,
        "exploitation_improvement_mm": (best_reward - best_before) if exploitation else float("nan"),
        "attempts": [_attempt_summary(a, b, limits) for a, b in zip(attempts, best, strict=True)],
        "tracking_mse_deg2": [a.tracking_mse_deg2 for a in attempts if math.isfinite(a.tracking_mse_deg2)],
        "inverse_map": {
            "snapshots": len(run.inverse_maps),
            "last_refinement": run.inverse_maps[-1].refinement if run.inverse_maps else None,
            "last_training_samples": run.inverse_maps[-1].training_samples if run.inverse_maps else None,
            "last_validation_rmse": run.inverse_maps[-1].validation_rmse if run.inverse_maps else None,
        },
        "configs": sorted(run.configs),
    }
    return _json_ready(summary)  # type: ignore[no-any-return]


@dataclass(frozen=True)
class Table:
    """One table of the summary, its cells as text.

    Attributes:
        header: the column names.
        rows: the rows, each with one cell per column.
    """

    header: tuple[str, ...]
    rows: list[tuple[str, ...]]


def _fmt(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def summary_tables(summary: Mapping[str, Any]) -> list[Table]:
    """The summary's tables: the key figures, then one row per attempt (when there are attempts).

    The markdown table (summary_markdown) and the report's index page show these.
    """
    babbling = summary["babbling"]
    rows = [
        ("run id", summary["run_id"]),
        ("recorded duration (s)", summary["duration_s"]),
        ("rig ticks", summary["ticks"]),
        ("babbling samples", babbling["samples"]),
        ("babbling duration (s)", babbling["duration_s"]),
        ("babbling samples within 5% of a limit", babbling["near_limit_fraction"]),
        ("threshold (mm)", f"{_fmt(summary['threshold_mm'])} ({summary['threshold_source']})"),
        ("attempts", summary["attempt_count"]),
        (
            "exploration / exploitation attempts",
            f"{summary['exploration_attempts']} / {summary['exploitation_attempts']}",
        ),
        ("attempts to cross the threshold", summary["attempts_to_threshold"]),
        ("best reward (mm)", summary["best_reward_mm"]),
        ("best attempt", summary["best_attempt"]),
        ("improvement during exploitation (mm)", summary["exploitation_improvement_mm"]),
        ("inverse-map snapshots", summary["inverse_map"]["snapshots"]),
        ("last validation RMSE", summary["inverse_map"]["last_validation_rmse"]),
    ]
    tables = [Table(("quantity", "value"), [(name, _fmt(value)) for name, value in rows])]
    if summary["attempts"]:
        columns = (
            ("attempt", "attempt"),
            ("phase", "phase"),
            ("control", "control"),
            ("ticks", "ticks"),
            ("reward (mm)", "reward_mm"),
            ("best (mm)", "best_reward_mm"),
            ("energy (J)", "energy_j"),
            ("tracking MSE (deg^2)", "tracking_mse_deg2"),
            ("tracking RMSE (rad)", "tracking_rmse_rad"),
            ("correction RMS (rad/s)", "correction_rms_rad_s"),
            ("sigma", "sigma"),
            ("near limit", "near_limit_fraction"),
            ("stop entries", "stop_entries"),
            ("fastest entry (rad/s)", "stop_entry_max_rad_s"),
            ("envelope ticks", "envelope_ticks"),
            ("trip", "trip"),
        )
        tables.append(
            Table(
                tuple(name for name, _ in columns),
                [tuple(_fmt(a[key]) for _, key in columns) for a in summary["attempts"]],
            )
        )
    return tables


def summary_markdown(summary: Mapping[str, Any]) -> str:
    """The summary as markdown: a key figures table, then one row per attempt."""
    lines = [f"# Run {summary['run_id']}"]
    for table in summary_tables(summary):
        lines += ["", "| " + " | ".join(table.header) + " |", "|" + " --- |" * len(table.header)]
        lines += ["| " + " | ".join(row) + " |" for row in table.rows]
    return "\n".join(lines) + "\n"


def _attempt_summary(a: RecordedAttempt, best: float, limits: FloatArray | None) -> dict[str, Any]:
    return {
        "attempt": a.attempt,
        "phase": a.phase,
        "ticks": len(a.recording),
        "reward_mm": a.reward_mm,
        "best_reward_mm": best,
        "energy_j": a.energy_j,
        "tracking_mse_deg2": a.tracking_mse_deg2,
        "tracking_rmse_rad": a.tracking_rmse_rad,
        "control": a.control,
        "correction_rms_rad_s": a.correction_rms_rad_s,
        "sigma": a.end.sigma if a.end is not None else float("nan"),
        "features": a.start.features.tolist(),
        "near_limit_fraction": (
            near_limit_fraction(a.recording.position_rad, limits) if limits is not None else float("nan")
        ),
        **_stop_entries(a.recording.position_rad, a.recording.velocity_rad_s, limits),
        "envelope_ticks": a.envelope_ticks,
        "trip": a.trip,
        "complete": a.end is not None,
    }


def _stop_entries(
    position_rad: FloatArray, velocity_rad_s: FloatArray, limits: FloatArray | None
) -> dict[str, Any]:
    """How often, and how hard, the joints entered their stops (g2p.rig.envelope.stop_entry_speeds)."""
    if limits is None or not len(position_rad):
        return {"stop_entries": 0, "stop_entry_max_rad_s": float("nan")}
    speeds = np.concatenate(
        [
            stop_entry_speeds(position_rad[:, j], velocity_rad_s[:, j], (limits[j, 0], limits[j, 1]))
            for j in range(2)
        ]
    )
    return {
        "stop_entries": len(speeds),
        "stop_entry_max_rad_s": float(speeds.max()) if len(speeds) else 0.0,
    }


def _segment_summary(t_s: FloatArray, position_rad: FloatArray, limits: FloatArray | None) -> dict[str, Any]:
    return {
        "samples": len(t_s),
        "duration_s": float(t_s[-1] - t_s[0]) if len(t_s) else 0.0,
        "near_limit_fraction": (
            near_limit_fraction(position_rad, limits) if limits is not None else float("nan")
        ),
    }


def _limits(value: Any) -> FloatArray | None:
    if value is None:
        return None
    try:
        limits = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return None
    if limits.shape != (2, 2) or not np.all(np.isfinite(limits)) or not np.all(limits[:, 0] < limits[:, 1]):
        return None
    return limits


def _find_key(value: Any, key: str) -> Any:
    """The first value stored under `key` anywhere in nested dicts/lists (depth first), else None."""
    if isinstance(value, Mapping):
        if key in value:
            return value[key]
        children: Iterable[Any] = value.values()
    elif isinstance(value, list):
        children = value
    else:
        return None
    for child in children:
        found = _find_key(child, key)
        if found is not None:
            return found
    return None


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _json_ready(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, np.floating | np.integer):
        return _json_ready(value.item())
    if isinstance(value, Mapping):
        return {str(k): _json_ready(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_ready(v) for v in value]
    return value
