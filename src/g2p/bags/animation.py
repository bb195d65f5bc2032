"""An animation of one attempt, from its bag alone: the leg as a stick figure on the belt, its time series.

Left: the leg (hip, knee, ankle, foot: `g2p.description.forward_kinematics` of each tick's joint angles)
above the belt, whose marks move with the belt displacement recorded since the attempt's first tick; the
desired foot path (the forward kinematics of the desired angles, drawn whole) with the desired posture
of the tick as a faint leg, and the actual foot path so far. Right: the joint angles, desired and actual,
and the belt travel since the first tick, against time, with a cursor at the frame's time. The title
names the attempt, its phase and its reward.

Frames sample rig time at a fixed rate (`FRAMES_PER_SECOND` frames per second of rig time, by the ticks'
stamps): frame i shows the last tick stamped at or before t0 + i / fps (t0: the attempt's first tick),
so an attempt whose stamps span S seconds has floor(S fps) + 1 frames (`frame_ticks`), or
floor(min(S, max_seconds) fps) + 1 when limited. Each frame lasts 1 / fps s, so the animation plays in
rig time. GIF through matplotlib's PillowWriter (pillow comes with matplotlib; the default, and
byte-for-byte the same from the same bag), or MP4 through FFMpegWriter when ffmpeg is installed. The
file is rendered to a temporary file in the target's directory and renamed over the target
(g2p.files.write_atomically).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib import animation as mpl_animation
from matplotlib.artist import Artist
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from numpy.typing import NDArray
from PIL import Image

from g2p.bags.dataset import RecordedAttempt
from g2p.bags.events import FloatArray
from g2p.description import LegDescription, forward_kinematics
from g2p.files import write_atomically
from g2p.plant import JOINT_NAMES

FRAMES_PER_SECOND = 10
"""Default frame rate (frames per second of rig time); the animation plays at this rate too."""
BELT_MARK_SPACING_M = 0.05
"""Distance between the belt's marks (m)."""
GIF, MP4 = ".gif", ".mp4"

_BELT_THICKNESS_M = 0.02
_FIGSIZE_IN = (9.6, 4.0)
_DPI = 80  # 768 x 320 pixels: small GIFs, and even sizes as H.264 needs
_STAMP_TOLERANCE_S = 1e-9  # frame times are sums of floats: a tick stamped exactly on one still counts


@dataclass(frozen=True)
class FrameGeometry:
    """What one frame draws on the left, in the belt frame (x, z) (m), belt surface z = 0.

    Attributes:
        tick: the tick shown (index into the attempt's recording).
        time_s: its time from the attempt's first tick (s).
        keypoints_m: hip, knee, ankle and foot of the leg at the tick, shape (4, 2).
        foot_path_m: the foot at every tick up to and including this one, shape (tick + 1, 2).
        desired_keypoints_m: the desired posture at the tick, shape (4, 2); None when no desired angles
            are recorded for it.
        desired_foot_path_m: the foot along the whole desired trajectory, shape (M, 2) ((0, 2) if none).
        belt_marks_x_m: x of the belt's marks within the view, shape (K,): marks every
            BELT_MARK_SPACING_M at belt travel 0, moved by -travel (the belt moves toward -x when the
            odometer counts up, docs/SIMULATOR.md).
        belt_travel_mm: belt displacement since the attempt's first tick (mm).
    """

    tick: int
    time_s: float
    keypoints_m: FloatArray
    foot_path_m: FloatArray
    desired_keypoints_m: FloatArray | None
    desired_foot_path_m: FloatArray
    belt_marks_x_m: FloatArray
    belt_travel_mm: float


def view_x_m(description: LegDescription) -> tuple[float, float]:
    """The stick figure's horizontal extent (m): the foot's reach either side of the hip."""
    return (-description.reach_m, description.reach_m)


def frame_ticks(
    t_s: FloatArray, fps: int = FRAMES_PER_SECOND, max_seconds: float | None = None
) -> NDArray[np.intp]:
    """The tick shown in each frame.

    Args:
        t_s: the attempt's tick stamps, in order, shape (N,) (s).
        fps: frames per second of rig time (a whole number: GIF and MP4 players need one).
        max_seconds: animate only the first this many seconds (None: the whole attempt).

    Returns:
        Tick indices, shape (F,), F = floor(min(S, max_seconds) fps) + 1 with S = t_s[-1] - t_s[0]
        (F = 0 for no ticks): frame i shows the last tick stamped at or before t_s[0] + i / fps.

    Raises:
        ValueError: fps is not a positive whole number, or max_seconds not a positive finite number.
    """
    if isinstance(fps, bool) or not isinstance(fps, int | np.integer) or fps <= 0:
        raise ValueError(f"frames per second must be a positive whole number, got {fps!r}")
    if max_seconds is not None and not (math.isfinite(max_seconds) and max_seconds > 0.0):
        raise ValueError(f"max_seconds must be positive and finite, got {max_seconds}")
    t = np.asarray(t_s, dtype=np.float64)
    if len(t) == 0:
        return np.zeros(0, dtype=np.intp)
    elapsed = t - t[0]
    span = float(elapsed[-1]) if max_seconds is None else min(float(elapsed[-1]), max_seconds)
    count = math.floor(span * fps + _STAMP_TOLERANCE_S) + 1
    frame_times = np.arange(count) / fps
    index = np.searchsorted(elapsed, frame_times + _STAMP_TOLERANCE_S, side="right") - 1
    return np.asarray(np.clip(index, 0, len(t) - 1), dtype=np.intp)


def belt_marks(travel_mm: float, x_min_m: float, x_max_m: float, spacing_m: float) -> FloatArray:
    """X of the belt's marks in [x_min_m, x_max_m] after `travel_mm` of belt travel, shape (K,) (m).

    At travel 0 the marks are at the multiples of `spacing_m`; travel moves them toward -x.
    """
    shift_m = travel_mm * 1e-3
    first = math.ceil((x_min_m + shift_m) / spacing_m - 1e-9)
    last = math.floor((x_max_m + shift_m) / spacing_m + 1e-9)
    return np.arange(first, last + 1, dtype=np.float64) * spacing_m - shift_m


def frame_geometry(description: LegDescription, attempt: RecordedAttempt, tick: int) -> FrameGeometry:
    """The stick figure, foot paths and belt marks of one tick of an attempt (what the left panel draws).

    Args:
        description: the leg that ran.
        attempt: the attempt; its desired row i belongs to tick i.
        tick: index into the attempt's recording, 0 <= tick < its length.

    Raises:
        IndexError: tick is out of range.
    """
    rec = attempt.recording
    if not 0 <= tick < len(rec):
        raise IndexError(f"tick {tick} is not in attempt {attempt.attempt} ({len(rec)} ticks)")
    path = forward_kinematics(description, rec.position_rad[: tick + 1])
    desired = attempt.desired_position_rad
    if desired is not None and len(desired):
        desired_fk = forward_kinematics(description, desired)
        desired_path, desired_now = desired_fk[:, 3], (desired_fk[tick] if tick < len(desired) else None)
    else:
        desired_path, desired_now = np.zeros((0, 2)), None
    travel_mm = float(rec.belt_mm[tick] - rec.belt_mm[0])
    return FrameGeometry(
        tick=tick,
        time_s=float(rec.t_s[tick] - rec.t_s[0]),
        keypoints_m=path[-1],
        foot_path_m=path[:, 3],
        desired_keypoints_m=desired_now,
        desired_foot_path_m=desired_path,
        belt_marks_x_m=belt_marks(travel_mm, *view_x_m(description), BELT_MARK_SPACING_M),
        belt_travel_mm=travel_mm,
    )


def mp4_available() -> bool:
    """Whether MP4 can be written (matplotlib finds ffmpeg)."""
    return bool(mpl_animation.writers.is_available("ffmpeg"))


def write_animation(
    attempt: RecordedAttempt,
    description: LegDescription,
    path: Path,
    fps: int = FRAMES_PER_SECOND,
    max_seconds: float | None = None,
) -> Path | None:
    """Render one attempt's animation to `path` (GIF, or MP4 for a `.mp4` path), atomically.

    Args:
        attempt: the attempt to show.
        description: the leg that ran (drawn by its forward kinematics).
        path: the file to write; its suffix picks the format (`.gif` or `.mp4`).
        fps: frames per second of rig time (and of playback).
        max_seconds: animate only the attempt's first this many seconds (None: all of it).

    Returns:
        `path`, or None when the attempt has no ticks (nothing is written).

    Raises:
        ValueError: the suffix is neither .gif nor .mp4, MP4 without ffmpeg, or invalid fps/max_seconds.
        OSError: the file cannot be written; a failure while rendering leaves no partial file and an
            existing file at `path` untouched.
    """
    ticks = frame_ticks(attempt.recording.t_s, fps, max_seconds)
    if len(ticks) == 0:
        return None
    suffix = path.suffix.lower()
    if suffix not in (GIF, MP4):
        raise ValueError(f"{path}: an animation is .gif or .mp4, not {path.suffix!r}")
    if suffix == MP4 and not mp4_available():
        raise ValueError(f"{path}: MP4 needs ffmpeg, which matplotlib does not find")
    # Rendered from inside write_atomically, so a failing frame leaves only the temporary file to clear.
    return write_atomically(path, lambda tmp: _render(attempt, description, ticks, fps, tmp))


def _render(
    attempt: RecordedAttempt,
    description: LegDescription,
    ticks: NDArray[np.intp],
    fps: int,
    out: Path,
) -> None:
    rec = attempt.recording
    t = rec.t_s - rec.t_s[0]
    span_s = max(float(t[ticks[-1]]), 1e-3)
    fig = Figure(figsize=_FIGSIZE_IN, dpi=_DPI)
    grid = fig.add_gridspec(3, 2, width_ratios=(1.15, 1.0), left=0.06, right=0.98, bottom=0.12, top=0.88)
    leg_ax = fig.add_subplot(grid[:, 0])
    series = [fig.add_subplot(grid[row, 1]) for row in range(3)]

    x_min, x_max = view_x_m(description)
    leg_ax.set_xlim(x_min, x_max)
    leg_ax.set_ylim(-2.5 * _BELT_THICKNESS_M, description.hip_height_m + 0.04)
    leg_ax.set_aspect("equal", adjustable="box")
    leg_ax.set_xlabel("x (m)")
    leg_ax.set_ylabel("z above the belt (m)")
    leg_ax.axhspan(-_BELT_THICKNESS_M, 0.0, color="0.8", zorder=0)
    leg_ax.axhline(0.0, color="0.3", linewidth=1.0, zorder=1)
    (marks,) = leg_ax.plot([], [], linestyle="", marker="|", markersize=7, color="0.3", zorder=1)
    first = frame_geometry(description, attempt, int(ticks[0]))
    has_desired = len(first.desired_foot_path_m) > 0
    if has_desired:
        leg_ax.plot(
            *first.desired_foot_path_m.T, "--", color="black", linewidth=1.0, label="desired foot path"
        )
    (ghost,) = leg_ax.plot(
        [], [], "-", color="0.6", linewidth=2.0, alpha=0.6, label="desired posture" if has_desired else None
    )
    (foot_path,) = leg_ax.plot([], [], "-", color="tab:blue", linewidth=1.2, label="foot path")
    (leg,) = leg_ax.plot(
        [], [], "-o", color="tab:orange", linewidth=3.0, markersize=5, markerfacecolor="white", label="leg"
    )
    hip = first.keypoints_m[0]
    leg_ax.plot([hip[0] - 0.04, hip[0] + 0.04], [hip[1] + 0.012] * 2, color="0.2", linewidth=3.0)  # carriage
    leg_ax.legend(loc="upper right", fontsize="x-small", frameon=False)

    desired = attempt.desired_position_rad
    for j, (ax, name) in enumerate(zip(series[:2], JOINT_NAMES, strict=True)):
        ax.plot(t, np.degrees(rec.position_rad[:, j]), color="tab:blue", linewidth=1.0, label="actual")
        if desired is not None:
            n = min(len(desired), len(t))
            ax.plot(t[:n], np.degrees(desired[:n, j]), "--", color="black", linewidth=1.0, label="desired")
        ax.set_ylabel(f"{name} (deg)", fontsize="small")
    series[0].legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), ncol=2, fontsize="x-small", frameon=False)
    series[2].plot(t, rec.belt_mm - rec.belt_mm[0], color="tab:green", linewidth=1.0)
    series[2].set_ylabel("belt (mm)", fontsize="small")
    series[2].set_xlabel("time from the attempt's first tick (s)")
    cursors = []
    for ax in series:
        ax.set_xlim(0.0, span_s)
        ax.tick_params(labelsize="x-small")
        cursors.append(ax.axvline(0.0, color="tab:red", linewidth=1.0))
    for ax in series[:2]:
        ax.tick_params(labelbottom=False)

    reward = f"{attempt.reward_mm:.1f} mm" if math.isfinite(attempt.reward_mm) else "not reported"
    heading = f"Attempt {attempt.attempt} ({attempt.phase or 'no phase'}), reward {reward}"
    title = fig.suptitle(heading)
    writer: mpl_animation.AbstractMovieWriter = (
        _GifWriter(fps, [marks, ghost, foot_path, leg, *cursors, title])
        if out.suffix.lower() == GIF
        else mpl_animation.FFMpegWriter(fps=fps)
    )
    marks_z = np.full(0, 0.0)
    with writer.saving(fig, str(out), dpi=_DPI):
        for tick in ticks:
            g = frame_geometry(description, attempt, int(tick))
            if len(marks_z) != len(g.belt_marks_x_m):
                marks_z = np.full(len(g.belt_marks_x_m), -0.5 * _BELT_THICKNESS_M)
            marks.set_data(g.belt_marks_x_m, marks_z)
            leg.set_data(*g.keypoints_m.T)
            foot_path.set_data(*g.foot_path_m.T)
            ghost.set_data(*(g.desired_keypoints_m.T if g.desired_keypoints_m is not None else ([], [])))
            for cursor in cursors:
                cursor.set_xdata([g.time_s, g.time_s])
            title.set_text(f"{heading}: t = {g.time_s:.2f} s")
            writer.grab_frame()


class _GifWriter(mpl_animation.PillowWriter):
    """matplotlib's PillowWriter, blitting, with every frame on the first frame's palette.

    Only `animated` artists change from frame to frame, so the rest of the figure is drawn once and each
    frame redraws those artists on a copy of it (the axes and their labels are most of a full draw's
    cost: 8x faster). With one palette, pixels that did not change keep their index, and Pillow's
    `optimize` writes them as transparent: a frame costs about what changed in it (4x smaller).
    """

    def __init__(self, fps: int, animated: list[Artist]) -> None:
        super().__init__(fps=fps)
        self.animated = animated
        self._images: list[Image.Image] = []
        self._palette: Image.Image | None = None

    def setup(self, fig: Figure, outfile: str, dpi: float | None = None) -> None:  # type: ignore[override]
        super().setup(fig, outfile, dpi)
        for artist in self.animated:
            artist.set_animated(True)
        self._canvas = FigureCanvasAgg(fig)
        self._canvas.draw()  # type: ignore[no-untyped-call]
        self._background = self._canvas.copy_from_bbox(fig.bbox)  # type: ignore[no-untyped-call]

    def grab_frame(self, **savefig_kwargs: object) -> None:
        self._canvas.restore_region(self._background)  # type: ignore[no-untyped-call]
        for artist in self.animated:
            self.fig.draw_artist(artist)
        size = self._canvas.get_width_height()
        rgba = self._canvas.buffer_rgba()  # type: ignore[no-untyped-call]
        rgb = Image.frombuffer("RGBA", size, rgba, "raw", "RGBA", 0, 1).convert("RGB")
        if self._palette is None:
            # 255 colours leave an index free for the transparency of unchanged pixels.
            self._palette = rgb.quantize(colors=255, dither=Image.Dither.NONE)
        self._images.append(rgb.quantize(palette=self._palette, dither=Image.Dither.NONE))

    def finish(self) -> None:
        self._images[0].save(
            self.outfile,
            save_all=True,
            append_images=self._images[1:],
            duration=round(1000 / self.fps),
            loop=0,
            optimize=True,
        )
