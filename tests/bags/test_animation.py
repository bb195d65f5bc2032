"""The attempt animation: frames at a known rate, the stick figure's known positions, atomic writes."""

from __future__ import annotations

import math
import os
import stat
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from matplotlib.figure import Figure
from PIL import Image

from g2p.bags import RecordedAttempt, load_run
from g2p.bags import animation as anim
from g2p.bags.animation import belt_marks, frame_geometry, frame_ticks, write_animation
from g2p.bags.events import RunEvent
from g2p.description import Joint, LegDescription, Link, forward_kinematics
from g2p.plant import Recording
from tests.bags.bagdata import SyntheticRun

RIG_HZ = 78.0


def leg() -> LegDescription:
    """A leg whose straight posture puts the foot on the belt: reach 0.2 + 0.18 + 0.03 + 0.01 = 0.42 m."""
    return LegDescription(
        hip_height_m=0.42,
        thigh=Link("thigh", 0.2, 0.01, 0.1, (0.0, -0.1), 1e-4),
        shank=Link("shank", 0.18, 0.01, 0.1, (0.0, -0.09), 1e-4),
        foot=Link("foot", 0.03, 0.01, 0.02, (0.0, -0.015), 1e-5),
        pad_half_length_m=0.02,
        joints=(Joint("proximal", -1.0, 1.0), Joint("distal", -2.0, 0.0)),
        belt_half_width_m=0.1,
    )


def event(kind: str, attempt: int, reward_mm: float = math.nan) -> RunEvent:
    nan = math.nan
    return RunEvent(
        0, 0, "run", kind, "exploration", attempt, np.zeros(0), reward_mm, nan, nan, nan, nan, nan
    )


def attempt_of(
    t_s: np.ndarray, position_rad: np.ndarray, belt_mm: np.ndarray, desired: np.ndarray | None = None
) -> RecordedAttempt:
    """Attempt 3 (reward 12.5 mm) made of the given ticks."""
    n = len(t_s)
    rec = Recording(
        t_s=np.asarray(t_s, dtype=np.float64),
        activation=np.zeros((n, 3)),
        position_rad=np.asarray(position_rad, dtype=np.float64),
        velocity_rad_s=np.zeros((n, 2)),
        belt_mm=np.asarray(belt_mm, dtype=np.float64),
        belt_velocity_mm_s=np.zeros(n),
        current_a=np.zeros((n, 3)),
        power_w=np.zeros((n, 3)),
        energy_j=np.zeros((n, 3)),
    )
    return RecordedAttempt(
        3, "exploration", event("attempt_start", 3), event("attempt_end", 3, 12.5), rec, desired
    )


def swinging(n: int) -> RecordedAttempt:
    """n ticks at 78 Hz from t = 1000 s: the hip swings, the belt runs at 39 mm/s."""
    t = 1000.0 + np.arange(n) / RIG_HZ
    q = np.stack([0.4 * np.sin(2 * np.pi * (t - 1000.0)), np.full(n, -0.3)], axis=1)
    return attempt_of(t, q, 39.0 * (t - 1000.0), desired=q + 0.05)


def test_frame_ticks_known_answer() -> None:
    t = 5.0 + 0.04 * np.arange(11)  # 25 Hz for 0.4 s
    # frame i at 0.1 i s shows tick floor(2.5 i), the last stamped at or before it
    np.testing.assert_array_equal(frame_ticks(t, fps=10), [0, 2, 5, 7, 10])
    np.testing.assert_array_equal(frame_ticks(t, fps=10, max_seconds=0.25), [0, 2, 5])
    assert len(frame_ticks(np.zeros(0))) == 0
    with pytest.raises(ValueError, match="whole number"):
        frame_ticks(t, fps=2.5)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="max_seconds"):
        frame_ticks(t, max_seconds=0.0)


@pytest.mark.parametrize(("fps", "max_seconds", "frames"), [(10, None, 21), (10, 1.0, 11), (4, None, 9)])
def test_gif_has_one_frame_per_step_of_rig_time(
    tmp_path: Path, fps: int, max_seconds: float | None, frames: int
) -> None:
    attempt = swinging(157)  # 156 tick periods at 78 Hz: 2.0 s
    path = write_animation(attempt, leg(), tmp_path / "a.gif", fps=fps, max_seconds=max_seconds)
    assert path == tmp_path / "a.gif"
    with Image.open(path) as gif:
        assert gif.format == "GIF"
        assert gif.n_frames == frames
        assert gif.size == (768, 320)
        assert gif.info["duration"] == round(1000 / fps)  # plays in rig time


def test_synthetic_attempt_frames_and_same_bytes_twice(synthetic_run: Callable[..., SyntheticRun]) -> None:
    run = load_run(synthetic_run().path)
    attempt = run.attempts[3]
    span_s = attempt.recording.t_s[-1] - attempt.recording.t_s[0]
    assert span_s == pytest.approx(49 * 0.012820513)  # 50 ticks
    first = write_animation(attempt, leg(), run.bag / "one.gif", fps=20)
    second = write_animation(attempt, leg(), run.bag / "two.gif", fps=20)
    assert first is not None and second is not None
    with Image.open(first) as gif:
        assert gif.n_frames == math.floor(span_s * 20) + 1 == 13
    assert first.read_bytes() == second.read_bytes()


def test_no_ticks_no_file(tmp_path: Path) -> None:
    empty = attempt_of(np.zeros(0), np.zeros((0, 2)), np.zeros(0))
    assert write_animation(empty, leg(), tmp_path / "a.gif") is None
    assert list(tmp_path.iterdir()) == []


def test_attempt_without_desired_angles(tmp_path: Path) -> None:
    swing = swinging(40)
    plain = attempt_of(swing.recording.t_s, swing.recording.position_rad, swing.recording.belt_mm)
    g = frame_geometry(leg(), plain, 10)
    assert g.desired_keypoints_m is None and g.desired_foot_path_m.shape == (0, 2)
    path = write_animation(plain, leg(), tmp_path / "a.gif")
    assert path is not None
    with Image.open(path) as gif:
        assert gif.n_frames == 6  # 39 periods at 78 Hz: 0.5 s


def test_frame_geometry_known_positions() -> None:
    straight, forward, knee_back = [0.0, 0.0], [np.pi / 2, 0.0], [0.0, -np.pi / 2]
    attempt = attempt_of(
        np.array([0.0, 0.1, 0.2]),
        np.array([straight, forward, knee_back]),
        np.array([100.0, 110.0, 125.0]),
        desired=np.array([straight, straight]),
    )
    g0 = frame_geometry(leg(), attempt, 0)
    # hanging straight: hip at its height, the foot's pad bottom on the belt at (0, hip - reach) = (0, 0)
    np.testing.assert_allclose(g0.keypoints_m, [[0, 0.42], [0, 0.22], [0, 0.04], [0, 0]], atol=1e-12)
    np.testing.assert_allclose(g0.foot_path_m, [[0, 0]], atol=1e-12)
    assert g0.time_s == 0.0 and g0.belt_travel_mm == 0.0
    # the hip at +90 deg holds the straight leg out toward +x
    g1 = frame_geometry(leg(), attempt, 1)
    np.testing.assert_allclose(
        g1.keypoints_m, [[0, 0.42], [0.2, 0.42], [0.38, 0.42], [0.42, 0.42]], atol=1e-12
    )
    np.testing.assert_allclose(g1.foot_path_m, [[0, 0], [0.42, 0.42]], atol=1e-12)
    np.testing.assert_allclose(g1.desired_keypoints_m, g0.keypoints_m, atol=1e-12)
    np.testing.assert_allclose(g1.desired_foot_path_m, [[0, 0], [0, 0]], atol=1e-12)
    assert g1.time_s == pytest.approx(0.1) and g1.belt_travel_mm == 10.0
    # 10 mm of travel moves the marks 10 mm toward -x: k * 0.05 - 0.01 m within the reach (+-0.42 m)
    np.testing.assert_allclose(g1.belt_marks_x_m, np.arange(-8, 9) * 0.05 - 0.01, atol=1e-12)
    # the knee at -90 deg points the shank and foot toward -x from the knee
    g2 = frame_geometry(leg(), attempt, 2)
    np.testing.assert_allclose(
        g2.keypoints_m, [[0, 0.42], [0, 0.22], [-0.18, 0.22], [-0.22, 0.22]], atol=1e-12
    )
    assert g2.desired_keypoints_m is None  # the desired trajectory has 2 rows
    assert g2.belt_travel_mm == 25.0
    with pytest.raises(IndexError):
        frame_geometry(leg(), attempt, 3)


def test_frame_geometry_is_forward_kinematics_of_the_tick(synthetic_run: Callable[..., SyntheticRun]) -> None:
    attempt = load_run(synthetic_run().path).attempts[0]
    q = attempt.recording.position_rad
    for k in frame_ticks(attempt.recording.t_s, fps=20):
        g = frame_geometry(leg(), attempt, int(k))
        np.testing.assert_array_equal(g.keypoints_m, forward_kinematics(leg(), q[k]))
        np.testing.assert_array_equal(g.foot_path_m, forward_kinematics(leg(), q[: k + 1])[:, 3])


def test_belt_marks_known_answer() -> None:
    np.testing.assert_allclose(belt_marks(0.0, -0.1, 0.1, 0.05), [-0.1, -0.05, 0.0, 0.05, 0.1], atol=1e-12)
    np.testing.assert_allclose(belt_marks(30.0, -0.1, 0.1, 0.05), [-0.08, -0.03, 0.02, 0.07], atol=1e-12)
    np.testing.assert_allclose(
        belt_marks(50.0, -0.1, 0.1, 0.05), belt_marks(0.0, -0.1, 0.1, 0.05), atol=1e-12
    )


def failing_after(calls: int) -> Callable[..., Any]:
    """Figure.draw_artist that raises on its `calls`-th call: the render fails part way through."""
    original = Figure.draw_artist
    count = 0

    def draw_artist(self: Figure, artist: Any) -> None:
        nonlocal count
        count += 1
        if count >= calls:
            raise RuntimeError("injected drawing failure")
        original(self, artist)

    return draw_artist


@pytest.fixture
def partial_files(monkeypatch: pytest.MonkeyPatch) -> list[tuple[Path, bool]]:
    """The files the GIF writer finished (path, whether they existed then): proof of a partial file."""
    finished: list[tuple[Path, bool]] = []
    original = anim._GifWriter.finish

    def finish(self: Any) -> None:
        original(self)
        finished.append((Path(self.outfile), Path(self.outfile).is_file()))

    monkeypatch.setattr(anim._GifWriter, "finish", finish)
    return finished


@pytest.mark.parametrize("existing", [False, True])
def test_failed_render_leaves_no_partial_file(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    partial_files: list[tuple[Path, bool]],
    existing: bool,
) -> None:
    target = tmp_path / "animation_best.gif"
    if existing:
        target.write_bytes(b"the previous animation")
    # 21 frames redraw a few artists each: the 50th draw is part way through
    monkeypatch.setattr(Figure, "draw_artist", failing_after(50))
    with pytest.raises(RuntimeError, match="injected drawing failure"):
        write_animation(swinging(157), leg(), target)
    # matplotlib's writer saved the frames it had (finish runs on the way out) into the temporary file
    [(partial, was_written)] = partial_files
    assert was_written and partial.parent == tmp_path and partial != target
    assert sorted(p.name for p in tmp_path.iterdir()) == (["animation_best.gif"] if existing else [])
    if existing:
        assert target.read_bytes() == b"the previous animation"


def test_successful_render_replaces_the_file(tmp_path: Path) -> None:
    target = tmp_path / "animation_best.gif"
    target.write_bytes(b"the previous animation")
    write_animation(swinging(20), leg(), target)
    assert [p.name for p in tmp_path.iterdir()] == ["animation_best.gif"]
    with Image.open(target) as gif:
        assert gif.n_frames == 3  # 19 periods at 78 Hz: 0.24 s
    assert stat.S_IMODE(os.stat(target).st_mode) == 0o644


def test_format_by_suffix(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"is \.gif or \.mp4"):
        write_animation(swinging(20), leg(), tmp_path / "a.png")
    if not anim.mp4_available():
        with pytest.raises(ValueError, match="ffmpeg"):
            write_animation(swinging(20), leg(), tmp_path / "a.mp4")
    assert list(tmp_path.iterdir()) == []
