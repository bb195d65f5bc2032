"""The report's figures (PNG), after the paper's Fig 4a, 4b, 5 and 6, drawn from a RunData.

Each function draws one figure into a file and returns its path, or returns None when the run lacks
the data (e.g. no attempts yet). Figures are drawn with matplotlib's object API (no pyplot state).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from g2p.bags.dataset import RecordedAttempt, RunData
from g2p.bags.events import FloatArray
from g2p.bags.summary import NEAR_LIMIT_BAND, best_so_far, near_limit_fraction
from g2p.plant import JOINT_NAMES

_PHASE_COLORS = {
    "exploration": "tab:gray",
    "exploitation": "tab:blue",
    "tracking": "tab:green",
    "testing": "tab:purple",
}
_DPI = 120


def reward_per_attempt(run: RunData, threshold_mm: float, path: Path) -> Path | None:
    """Fig 4a: each attempt's reward, the best so far, and the threshold."""
    attempts = [a for a in run.attempts if math.isfinite(a.reward_mm)]
    if not attempts:
        return None
    fig = Figure(figsize=(7, 4))
    ax = fig.add_subplot()
    for phase in sorted({a.phase for a in attempts}):
        chosen = [a for a in attempts if a.phase == phase]
        ax.plot(
            [a.attempt for a in chosen],
            [a.reward_mm for a in chosen],
            "o",
            color=_PHASE_COLORS.get(phase, "tab:orange"),
            label=phase or "attempt",
        )
    ax.step(
        [a.attempt for a in attempts],
        best_so_far(a.reward_mm for a in attempts),
        where="post",
        color="black",
        label="best so far",
    )
    ax.axhline(threshold_mm, color="tab:red", linestyle="--", label=f"threshold {threshold_mm:g} mm")
    ax.set_xlabel("attempt")
    ax.set_ylabel("reward: belt travel (mm)")
    ax.set_title(f"Reward per attempt (run {run.run_id})")
    ax.legend(loc="best", fontsize="small")
    return _save(fig, path)


def reward_vs_energy(run: RunData, threshold_mm: float, path: Path) -> Path | None:
    """Fig 4b: reward against energy; exploitation attempts above the threshold highlighted."""
    attempts = [a for a in run.attempts if math.isfinite(a.reward_mm) and math.isfinite(a.energy_j)]
    if not attempts:
        return None
    fig = Figure(figsize=(6, 4.5))
    ax = fig.add_subplot()
    above = [a for a in attempts if a.phase == "exploitation" and a.reward_mm > threshold_mm]
    rest = [a for a in attempts if a not in above]
    ax.plot(
        [a.energy_j for a in rest],
        [a.reward_mm for a in rest],
        "o",
        color="tab:gray",
        alpha=0.7,
        label="other attempts",
    )
    ax.plot(
        [a.energy_j for a in above],
        [a.reward_mm for a in above],
        "o",
        color="tab:blue",
        label="exploitation, above threshold",
    )
    ax.axhline(threshold_mm, color="tab:red", linestyle="--", label=f"threshold {threshold_mm:g} mm")
    ax.set_xlabel("energy (J)")
    ax.set_ylabel("reward: belt travel (mm)")
    ax.set_title("Reward vs energy")
    ax.legend(loc="best", fontsize="small")
    return _save(fig, path)


def tracking(attempt: RecordedAttempt, path: Path) -> Path | None:
    """Fig 5a: desired and actual joint angles of one attempt, against time from its first tick."""
    rec = attempt.recording
    if len(rec) == 0:
        return None
    t = rec.t_s - rec.t_s[0]
    fig = Figure(figsize=(8, 5))
    axes = fig.subplots(len(JOINT_NAMES), 1, sharex=True)
    for j, (ax, name) in enumerate(zip(axes, JOINT_NAMES, strict=True)):
        ax.plot(t, np.degrees(rec.position_rad[:, j]), color="tab:blue", label="actual")
        if attempt.desired_position_rad is not None:
            desired = attempt.desired_position_rad
            n = min(len(desired), len(t))
            ax.plot(t[:n], np.degrees(desired[:n, j]), "--", color="black", label="desired")
        ax.set_ylabel(f"{name} (deg)")
        ax.legend(loc="upper right", fontsize="small")
    axes[-1].set_xlabel("time from the attempt's first tick (s)")
    note = "" if attempt.desired_position_rad is not None else " (no desired trajectory recorded)"
    fig.suptitle(f"Attempt {attempt.attempt} ({attempt.phase}): joint angles{note}")
    return _save(fig, path)


def tracking_mse(run: RunData, path: Path) -> Path | None:
    """Fig 5b: tracking MSE per attempt (each attempt refines the map) for tracking runs."""
    attempts = [a for a in run.attempts if math.isfinite(a.tracking_mse_deg2)]
    if not attempts:
        return None
    fig = Figure(figsize=(6, 4))
    ax = fig.add_subplot()
    ax.plot([a.attempt for a in attempts], [a.tracking_mse_deg2 for a in attempts], "o-", color="tab:green")
    ax.set_xlabel("attempt")
    ax.set_ylabel("tracking MSE (deg$^2$)")
    ax.set_title("Tracking error per refinement")
    return _save(fig, path)


def angle_distribution(
    run: RunData, attempt: RecordedAttempt | None, limits_rad: FloatArray | None, path: Path
) -> Path | None:
    """Fig 6: distribution of each joint's angle in babbling and in one attempt, with the 5% bands."""
    if len(run.babbling) == 0 or limits_rad is None:
        return None
    fig = Figure(figsize=(8, 4))
    axes = fig.subplots(1, len(JOINT_NAMES))
    sets = [("babbling", run.babbling.position_rad, "tab:gray")]
    if attempt is not None and len(attempt.recording):
        sets.append((f"attempt {attempt.attempt}", attempt.recording.position_rad, "tab:blue"))
    for j, (ax, name) in enumerate(zip(axes, JOINT_NAMES, strict=True)):
        low, high = np.degrees(limits_rad[j])
        band = NEAR_LIMIT_BAND * (high - low)
        ax.axvspan(low, low + band, color="tab:red", alpha=0.15)
        ax.axvspan(high - band, high, color="tab:red", alpha=0.15, label="within 5% of a limit")
        bins = np.linspace(low, high, 41)
        for label, q, color in sets:
            fraction = near_limit_fraction(q, limits_rad)
            ax.hist(
                np.clip(np.degrees(q[:, j]), low, high),
                bins=bins,
                density=True,
                alpha=0.5,
                color=color,
                label=f"{label} ({100 * fraction:.1f}% near a limit)",
            )
        ax.set_xlabel(f"{name} angle (deg)")
        ax.set_ylabel("density")
        ax.legend(loc="upper center", fontsize="x-small")
    fig.suptitle("Joint-angle distribution")
    return _save(fig, path)


def _save(fig: Figure, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=_DPI)
    return path
