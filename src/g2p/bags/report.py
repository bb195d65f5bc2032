"""A run's summary (JSON and markdown), figures and animations, from its bag alone; the `g2p-report` command.

    g2p-report bags/<run> [--attempt K] [--animate best|K ...] [--no-animation] [--out DIR]

Writes `bags/<run>/summary.json` and `bags/<run>/report/`: summary.md, the figures (PNG), an animation
of the best attempt (GIF, g2p.bags.animation) and index.html, a page showing them all. A bag that
cannot be read gives one line on stderr and exit status 2. Needs no ROS.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

from g2p.bags import animation, plots
from g2p.bags.dataset import RecordedAttempt, RunData, load_run
from g2p.bags.errors import BagError
from g2p.bags.index_page import IndexEntry, index_html
from g2p.bags.runs import report_dir, summary_path
from g2p.bags.summary import find_joint_limits, find_threshold, summarize, summary_markdown
from g2p.description import LegDescription
from g2p.description.urdf import UrdfError, packaged_leg_description
from g2p.files import write_text_atomically
from g2p.rig import DEFAULT_NAMESPACE

FIGURES = (
    "fig4a_reward.png",
    "fig4b_reward_energy.png",
    "fig5a_tracking.png",
    "fig5b_tracking_mse.png",
    "fig6_angle_distribution.png",
)
CAPTIONS = {
    "fig4a_reward.png": "Reward (belt travel) per attempt by phase, the best so far and the threshold "
    "(paper Fig 4a).",
    "fig4b_reward_energy.png": "Reward against energy; exploitation attempts above the threshold "
    "highlighted (Fig 4b).",
    "fig5a_tracking.png": "Desired and actual joint angles of one attempt (Fig 5a).",
    "fig5b_tracking_mse.png": "Tracking MSE per attempt, i.e. per refinement of the map (Fig 5b).",
    "fig6_angle_distribution.png": "Joint-angle distribution, babbling against one attempt, with the "
    "bands within 5% of a limit (Fig 6).",
}
BEST_ANIMATION = "animation_best"
INDEX_HTML = "index.html"


def animation_name(attempt: int | None, mp4: bool = False) -> str:
    """The file name of an animation: `animation_best.gif` (attempt None) or `animation_attempt_<K>.gif`."""
    stem = BEST_ANIMATION if attempt is None else f"animation_attempt_{attempt}"
    return stem + (animation.MP4 if mp4 else animation.GIF)


@dataclass(frozen=True)
class AnimationOptions:
    """Which attempts a report animates, and how (g2p.bags.animation).

    Attributes:
        best: animate the best attempt (the highest reward among attempts with ticks; when none has a
            reward, the last with ticks) into `report/animation_best.gif`.
        attempts: also animate these attempts, each into `report/animation_attempt_<K>.gif`.
        fps: frames per second of rig time (and of playback).
        max_seconds: animate only each attempt's first this many seconds (s); None: all of it.
        mp4: write MP4 (`.mp4`) when matplotlib finds ffmpeg; GIF otherwise, and by default.
    """

    best: bool = True
    attempts: tuple[int, ...] = ()
    fps: int = animation.FRAMES_PER_SECOND
    max_seconds: float | None = None
    mp4: bool = False

    def __post_init__(self) -> None:
        if isinstance(self.fps, bool) or not isinstance(self.fps, int) or self.fps <= 0:
            raise ValueError(f"fps: must be a positive whole number, got {self.fps!r}")
        if self.max_seconds is not None and not (math.isfinite(self.max_seconds) and self.max_seconds > 0.0):
            raise ValueError(f"max_seconds: must be positive and finite, got {self.max_seconds}")


NO_ANIMATIONS = AnimationOptions(best=False)


@dataclass(frozen=True)
class ReportResult:
    """Where a report was written.

    Attributes:
        summary_json: the summary (JSON).
        summary_markdown: the summary table (markdown).
        figures: the figures written (PNG).
        skipped: figures and animations not drawn for lack of data, with the reason.
        animations: the animations written.
        index: the index page (HTML) showing the summary, the figures and the animations.
    """

    summary_json: Path
    summary_markdown: Path
    figures: list[Path]
    skipped: dict[str, str]
    animations: list[Path] = field(default_factory=list)
    index: Path | None = None


def write_report(
    bag: Path | str,
    attempt: int | None = None,
    rig_namespace: str = DEFAULT_NAMESPACE,
    out_dir: Path | None = None,
    animations: AnimationOptions = AnimationOptions(),
) -> ReportResult:
    """Write `summary.json` beside the bag and `report/`: the figures, the animations, summary.md, index.html.

    Args:
        bag: the bag directory (the run directory).
        attempt: the attempt shown in Fig 5a and 6; None for the last attempt with a desired trajectory,
            else the best attempt.
        rig_namespace: namespace of the rig topics.
        out_dir: write there instead of into the run directory (summary.json and report/ inside it).
        animations: which attempts to animate (default: the best one, GIF).

    Raises:
        BagReadError: the bag cannot be read.
        BagError: an attempt does not exist, or the outputs cannot be written.
    """
    run = load_run(bag, rig_namespace)
    root = Path(out_dir) if out_dir is not None else Path(bag)
    figures_dir = report_dir(root)
    summary = summarize(run)
    threshold, _ = find_threshold(run)
    limits, _ = find_joint_limits(run)
    shown = _shown_attempt(run, attempt)
    for k in animations.attempts:
        _find_attempt(run, k)  # an unknown attempt fails before anything is drawn
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
    summary["leg_description"] = "bag" if run.leg_description is not None else "packaged"

    written, movies = _animate(run, figures_dir, animations, root)
    for movie in movies:
        if movie.skipped is not None:
            skipped[movie.name] = movie.skipped
        summary["figures"][movie.name] = (
            "report/" + movie.name if movie.skipped is None else f"skipped: {movie.skipped}"
        )
    summary["animated_attempts"] = {p.name: k for p, k in written}

    entries = [IndexEntry(name, CAPTIONS[name], skipped.get(name)) for name in FIGURES]
    try:
        json_path = write_text_atomically(
            summary_path(root), json.dumps(summary, indent=2, allow_nan=False) + "\n"
        )
        md_path = write_text_atomically(figures_dir / "summary.md", summary_markdown(summary))
        index = write_text_atomically(figures_dir / INDEX_HTML, index_html(summary, entries, movies))
    except OSError as err:
        raise BagError(f"cannot write the report: {err}", root) from err
    return ReportResult(json_path, md_path, figures, skipped, [p for p, _ in written], index)


def _animate(
    run: RunData, figures_dir: Path, options: AnimationOptions, root: Path
) -> tuple[list[tuple[Path, int]], list[IndexEntry]]:
    """Write the animations `options` ask for.

    Returns:
        Each animation written with its attempt number, and an index entry for each one asked for
        (those not drawn with the reason).
    """
    mp4 = options.mp4 and animation.mp4_available()
    wanted = [(animation_name(None, mp4), _best_attempt(run))] if options.best else []
    wanted += [(animation_name(k, mp4), _find_attempt(run, k)) for k in options.attempts]
    description = _description(run) if any(a is not None for _, a in wanted) else None
    written: list[tuple[Path, int]] = []
    entries = []
    for name, chosen in wanted:
        path = None
        if chosen is not None and description is not None:
            try:
                path = animation.write_animation(
                    chosen, description, figures_dir / name, options.fps, options.max_seconds
                )
            except OSError as err:
                raise BagError(f"cannot write the animation {name}: {err}", root) from err
        if path is None or chosen is None:
            entries.append(IndexEntry(name, "", "no attempt ticks"))
            continue
        written.append((path, chosen.attempt))
        entries.append(IndexEntry(name, _animation_caption(chosen, name, options)))
    return written, entries


def _description(run: RunData) -> LegDescription:
    """The leg to draw: the bag's robot_description, else the packaged URDF (bags recorded before it)."""
    if run.leg_description is not None:
        return run.leg_description
    try:
        return packaged_leg_description()
    except (OSError, UrdfError) as err:
        raise BagError(f"no robot_description in the bag, and no packaged leg: {err}") from err


def _animation_caption(attempt: RecordedAttempt, name: str, options: AnimationOptions) -> str:
    best = ", the best" if name.startswith(BEST_ANIMATION) else ""
    reward = f"{attempt.reward_mm:.1f} mm" if math.isfinite(attempt.reward_mm) else "not reported"
    span = f"its first {options.max_seconds:g} s" if options.max_seconds is not None else "all of it"
    return (
        f"Attempt {attempt.attempt}{best} ({attempt.phase or 'no phase'}, reward {reward}), {span}, "
        f"{options.fps} frames per second of rig time, played in rig time. Left: the leg on the belt, the "
        "desired foot path (dashed) and the actual one so far. Right: desired and actual joint angles and "
        "the belt travel."
    )


def _best_attempt(run: RunData) -> RecordedAttempt | None:
    """The attempt with the highest reward among those with ticks (the first of equals).

    When none has a reward, the last with ticks; None when no attempt has ticks.
    """
    with_ticks = [a for a in run.attempts if len(a.recording)]
    rewarded = [a for a in with_ticks if math.isfinite(a.reward_mm)]
    if rewarded:
        return max(rewarded, key=lambda a: a.reward_mm)
    return with_ticks[-1] if with_ticks else None


def _find_attempt(run: RunData, attempt: int) -> RecordedAttempt:
    found = [a for a in run.attempts if a.attempt == attempt]
    if not found:
        raise BagError(
            f"attempt {attempt} is not in the run (attempts: "
            f"{', '.join(str(a.attempt) for a in run.attempts) or 'none'})",
            run.bag,
        )
    return found[-1]


def _shown_attempt(run: RunData, attempt: int | None) -> RecordedAttempt | None:
    if attempt is not None:
        return _find_attempt(run, attempt)
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
        description="Summary (JSON, markdown), figures (PNG), animations (GIF) and an index page "
        "(report/index.html) of a recorded run, from its bag.",
    )
    parser.add_argument("bag", type=Path, help="the run's bag directory (bags/<run-id>)")
    parser.add_argument(
        "--attempt",
        type=int,
        default=None,
        help="attempt shown in the tracking and angle-distribution figures (default: the last "
        "with a desired trajectory, else the best)",
    )
    parser.add_argument(
        "--animate",
        action="append",
        type=_animated,
        metavar="best|K",
        help="animate the best attempt ('best') or attempt K; repeat for several (default: best)",
    )
    parser.add_argument("--no-animation", action="store_true", help="write no animation")
    parser.add_argument(
        "--animation-seconds",
        type=float,
        default=None,
        metavar="S",
        help="animate only each attempt's first S seconds of rig time (default: all of it)",
    )
    parser.add_argument(
        "--animation-fps",
        type=int,
        default=animation.FRAMES_PER_SECOND,
        metavar="F",
        help=f"frames per second of rig time (default {animation.FRAMES_PER_SECOND})",
    )
    parser.add_argument(
        "--mp4", action="store_true", help="MP4 instead of GIF when ffmpeg is installed (GIF otherwise)"
    )
    parser.add_argument("--namespace", default=DEFAULT_NAMESPACE, help="namespace of the rig topics")
    parser.add_argument("--out", type=Path, default=None, help="write here instead of into the bag directory")
    ns = parser.parse_args(sys.argv[1:] if args is None else args)
    if ns.no_animation and ns.animate:
        parser.error("--no-animation and --animate exclude each other")
    chosen = ns.animate or ["best"]
    try:
        options = (
            NO_ANIMATIONS
            if ns.no_animation
            else AnimationOptions(
                best="best" in chosen,
                attempts=tuple(dict.fromkeys(k for k in chosen if isinstance(k, int))),
                fps=ns.animation_fps,
                max_seconds=ns.animation_seconds,
                mp4=ns.mp4,
            )
        )
    except ValueError as err:
        parser.error(str(err))
    try:
        result = write_report(
            ns.bag, attempt=ns.attempt, rig_namespace=ns.namespace, out_dir=ns.out, animations=options
        )
    except BagError as err:
        print(f"g2p-report: error: {err}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        sys.exit(130)
    print(f"summary: {result.summary_json}")
    print(f"table:   {result.summary_markdown}")
    for figure in result.figures:
        print(f"figure:  {figure}")
    for path in result.animations:
        print(f"animation: {path}")
    for name, reason in result.skipped.items():
        print(f"skipped: {name} ({reason})")
    print(f"index:   {result.index}")


def _animated(text: str) -> str | int:
    """An --animate value: "best" or an attempt number."""
    if text == "best":
        return text
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'best' or an attempt number, not {text!r}") from None


if __name__ == "__main__":
    main()
