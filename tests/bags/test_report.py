"""The report of a synthetic run: summary numbers are known answers, every figure is a PNG."""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable
from dataclasses import replace
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image

from g2p.bags import (
    BagError,
    BagWriter,
    RecordedAttempt,
    TopicSpec,
    TypeRegistry,
    animation,
    load_run,
    write_report,
)
from g2p.bags.report import FIGURES, NO_ANIMATIONS, AnimationOptions
from g2p.bags.report import main as report_main
from g2p.bags.summary import best_so_far, find_joint_limits, find_threshold, near_limit_fraction
from g2p.description import LegDescription
from g2p.description.urdf import leg_urdf, packaged_leg_description
from tests.bags.bagdata import Messages, SyntheticRun
from tests.commands import console_script

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture
def run(synthetic_run: Callable[..., SyntheticRun]) -> SyntheticRun:
    return synthetic_run()


def test_summary_known_answers(run: SyntheticRun) -> None:
    result = write_report(run.path)
    summary = json.loads(result.summary_json.read_text())
    assert result.summary_json == run.path / "summary.json"
    assert summary["run_id"] == "run-1"
    assert summary["threshold_mm"] == 64.0 and summary["threshold_source"] == "run_start event"
    assert summary["joint_limits_rad"] == [[-1.0, 1.0], [-1.5, 0.0]]
    assert summary["babbling"]["samples"] == 200
    assert summary["babbling"]["near_limit_fraction"] == pytest.approx(0.8)  # k % 5 != 0 sit at a limit
    assert summary["attempt_count"] == 5
    assert (summary["exploration_attempts"], summary["exploitation_attempts"]) == (3, 2)
    assert summary["attempts_to_threshold"] == 3  # 70 mm > 64 mm
    assert summary["best_reward_mm"] == 90.0 and summary["best_attempt"] == 4
    assert summary["exploitation_improvement_mm"] == 20.0
    assert [a["best_reward_mm"] for a in summary["attempts"]] == [10.0, 30.0, 70.0, 90.0, 90.0]
    assert [a["ticks"] for a in summary["attempts"]] == [50] * 5
    assert [a["envelope_ticks"] for a in summary["attempts"]] == [5] * 5
    assert [a["trip"] for a in summary["attempts"]] == [""] * 5
    assert summary["tracking_mse_deg2"] == [100.0 / k for k in range(1, 6)]
    assert [a["control"] for a in summary["attempts"]] == ["open"] * 3 + ["closed"] * 2
    corrections = [a["correction_rms_rad_s"] for a in summary["attempts"]]
    assert corrections[:3] == [None] * 3  # NaN in the JSON: open loop has no correction
    assert corrections[3:] == pytest.approx([0.4 / np.sqrt(2), 0.5 / np.sqrt(2)])
    assert summary["inverse_map"]["snapshots"] == 6 and summary["inverse_map"]["last_refinement"] == 5
    assert summary["incomplete_ticks"] == 1
    assert summary["configs"] == ["/leg/learner/config"]
    assert summary["messages"]["/leg/learner/events"] == 2 + 1 + 10 + 1


def test_figures_and_markdown(run: SyntheticRun) -> None:
    result = write_report(run.path)
    assert result.skipped == {}
    assert sorted(p.name for p in result.figures) == sorted(FIGURES)
    for figure in result.figures:
        assert figure.parent == run.path / "report"
        assert figure.read_bytes()[:8] == PNG_MAGIC
    table = result.summary_markdown.read_text()
    assert "| attempts to cross the threshold | 3 |" in table
    assert "| 4 | exploitation | closed | 50 | 90 | 90 | 8 | 25 | - | 0.2828 | 0.1 |" in table


def test_report_shows_requested_attempt(run: SyntheticRun, tmp_path: Path) -> None:
    result = write_report(run.path, attempt=2, out_dir=tmp_path / "out")
    assert json.loads(result.summary_json.read_text())["report_attempt"] == 2
    assert result.summary_json == tmp_path / "out" / "summary.json"
    with pytest.raises(BagError, match="attempt 9 is not in the run"):
        write_report(run.path, attempt=9)


def test_threshold_and_limits_from_run_start(run: SyntheticRun) -> None:
    data = load_run(run.path)
    assert find_threshold(data) == (64.0, "run_start event")
    limits, source = find_joint_limits(data)
    assert source == "run_start event"
    np.testing.assert_array_equal(limits, [[-1.0, 1.0], [-1.5, 0.0]])


def test_rig_only_bag_skips_learner_figures(
    tmp_path: Path, registry: TypeRegistry, messages: Messages
) -> None:
    bag = tmp_path / "rig-only"
    with BagWriter(bag) as writer:
        handle = writer.add_topic(
            TopicSpec("/leg/treadmill", registry.definition("g2p_interfaces/msg/Treadmill"))
        )
        writer.write(
            handle,
            1,
            messages.cdr(
                messages.make(
                    "g2p_interfaces/msg/Treadmill",
                    header=messages.header(1),
                    displacement_mm=1.0,
                    velocity_mm_s=0.0,
                )
            ),
        )
    result = write_report(bag)
    assert result.figures == [] and result.animations == []
    assert set(result.skipped) == {*FIGURES, "animation_best.gif"}
    summary = json.loads(result.summary_json.read_text())
    assert summary["attempt_count"] == 0 and summary["threshold_source"] == "paper default"
    assert summary["figures"]["fig4a_reward.png"] == "skipped: no attempt rewards"
    assert summary["figures"]["animation_best.gif"] == "skipped: no attempt ticks"
    assert summary["animated_attempts"] == {}
    page = IndexLinks.of(result.index)
    assert page.targets == set() and "animation_best.gif</code>: not drawn (no attempt ticks)" in page.text


def test_near_limit_fraction_known_answer() -> None:
    limits = np.array([[0.0, 10.0], [-1.0, 1.0]])
    q = np.array(
        [[0.4, 0.0], [5.0, 0.95], [9.6, 0.0], [5.0, 0.0]]
    )  # near low, near high (joint 2), near high, none
    assert near_limit_fraction(q, limits) == 0.75
    assert np.isnan(near_limit_fraction(np.zeros((0, 2)), limits))


def test_best_so_far_ignores_nan() -> None:
    assert best_so_far([float("nan"), 3.0, 1.0, float("nan"), 5.0])[1:] == [3.0, 3.0, 3.0, 5.0]


def test_report_cli_writes_everything(run: SyntheticRun) -> None:
    done = subprocess.run(
        [str(console_script("g2p-report")), str(run.path)], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    report = run.path / "report"
    assert f"summary: {run.path / 'summary.json'}" in done.stdout
    assert all((report / name).is_file() for name in FIGURES)
    lines = done.stdout.splitlines()
    assert f"animation: {report / 'animation_best.gif'}" in lines
    assert lines[-1] == f"index:   {report / 'index.html'}"


def test_report_animates_the_best_attempt(run: SyntheticRun) -> None:
    result = write_report(run.path)
    best = run.path / "report" / "animation_best.gif"
    assert result.animations == [best]
    with Image.open(best) as gif:
        assert gif.n_frames == 7  # 50 ticks, 0.628 s, at 10 frames per second: frames at 0, 0.1, ..., 0.6 s
    summary = json.loads(result.summary_json.read_text())
    assert summary["figures"]["animation_best.gif"] == "report/animation_best.gif"
    assert summary["animated_attempts"] == {"animation_best.gif": 4}  # the 90 mm attempt
    assert summary["leg_description"] == "packaged"  # the synthetic bag has no robot_description


def test_report_animates_requested_attempts(run: SyntheticRun, tmp_path: Path) -> None:
    options = AnimationOptions(best=False, attempts=(2, 5), fps=20, max_seconds=0.3)
    result = write_report(run.path, out_dir=tmp_path, animations=options)
    report = tmp_path / "report"
    assert result.animations == [report / "animation_attempt_2.gif", report / "animation_attempt_5.gif"]
    for path in result.animations:
        with Image.open(path) as gif:
            assert gif.n_frames == 7  # 0.3 s at 20 frames per second
    assert not (report / "animation_best.gif").exists()
    summary = json.loads(result.summary_json.read_text())
    assert summary["animated_attempts"] == {"animation_attempt_2.gif": 2, "animation_attempt_5.gif": 5}
    with pytest.raises(BagError, match="attempt 9 is not in the run"):
        write_report(run.path, out_dir=tmp_path / "again", animations=AnimationOptions(attempts=(9,)))
    assert not (tmp_path / "again").exists()  # nothing drawn
    assert write_report(run.path, out_dir=tmp_path / "none", animations=NO_ANIMATIONS).animations == []


def test_leg_description_from_the_bag(
    synthetic_run: Callable[..., SyntheticRun], monkeypatch: pytest.MonkeyPatch
) -> None:
    ours = replace(packaged_leg_description(), hip_height_m=0.5)
    assert ours != packaged_leg_description()
    run = synthetic_run(robot_descriptions=(leg_urdf(ours),))
    drawn: list[LegDescription] = []
    original = animation.write_animation

    def spy(attempt: RecordedAttempt, description: LegDescription, *args: Any) -> Path | None:
        drawn.append(description)
        return original(attempt, description, *args)

    monkeypatch.setattr(animation, "write_animation", spy)
    result = write_report(run.path)
    assert drawn == [ours]
    summary = json.loads(result.summary_json.read_text())
    assert summary["leg_description"] == "bag"
    assert "robot_description</code> (the URDF the rig published)" in result.index.read_text()


def test_packaged_leg_description_without_one_in_the_bag(run: SyntheticRun) -> None:
    assert "packaged URDF" in write_report(run.path).index.read_text()


class IndexLinks(HTMLParser):
    """The links (href, src) and text of an HTML page."""

    def __init__(self) -> None:
        super().__init__()
        self.targets: set[str] = set()
        self.text = ""

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.targets |= {v for k, v in attrs if k in ("href", "src") and v is not None}

    @classmethod
    def of(cls, page: Path | None) -> IndexLinks:
        assert page is not None
        parser = cls()
        parser.text = page.read_text()
        parser.feed(parser.text)
        parser.targets -= {"../summary.json", "summary.md"}
        assert (page.parent / "summary.md").is_file() and (page.parent.parent / "summary.json").is_file()
        return parser


def test_index_page_shows_every_figure_and_the_animation(run: SyntheticRun) -> None:
    result = write_report(run.path)
    assert result.index == run.path / "report" / "index.html"
    page = IndexLinks.of(result.index)
    written = {p.name for p in [*result.figures, *result.animations]}
    assert written == {*FIGURES, "animation_best.gif"}
    assert page.targets == written
    assert all((result.index.parent / target).is_file() for target in page.targets)
    assert "<h1>Run run-1</h1>" in page.text
    assert "<tr><td>attempts to cross the threshold</td><td>3</td></tr>" in page.text
    assert "<tr><td>4</td><td>exploitation</td><td>closed</td><td>50</td><td>90</td>" in page.text
    assert "Attempt 4, the best (exploitation, reward 90.0 mm)" in page.text
    assert not [p for p in result.index.parent.iterdir() if ".tmp" in p.name]


def test_report_cli_options(run: SyntheticRun, capsys: pytest.CaptureFixture[str]) -> None:
    report_main([str(run.path), "--animate", "2", "--animate", "best", "--animation-fps", "20"])
    out = capsys.readouterr().out.splitlines()
    report = run.path / "report"
    assert [line for line in out if line.startswith("animation:")] == [
        f"animation: {report / 'animation_best.gif'}",
        f"animation: {report / 'animation_attempt_2.gif'}",
    ]
    with Image.open(report / "animation_attempt_2.gif") as gif:
        assert gif.n_frames == 13  # 0.628 s at 20 frames per second
    with pytest.raises(SystemExit) as stopped:
        report_main([str(run.path), "--animate", "9"])
    assert stopped.value.code == 2
    assert "attempt 9 is not in the run" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stopped:
        report_main([str(run.path), "--animate", "2", "--no-animation"])
    assert stopped.value.code == 2 and "exclude each other" in capsys.readouterr().err
