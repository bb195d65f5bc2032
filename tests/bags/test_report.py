"""The report of a synthetic run: summary numbers are known answers, every figure is a PNG."""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from g2p.bags import BagError, BagWriter, TopicSpec, TypeRegistry, load_run, write_report
from g2p.bags.report import FIGURES
from g2p.bags.summary import best_so_far, find_joint_limits, find_threshold, near_limit_fraction
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
    assert result.figures == []
    assert set(result.skipped) == set(FIGURES)
    summary = json.loads(result.summary_json.read_text())
    assert summary["attempt_count"] == 0 and summary["threshold_source"] == "paper default"
    assert summary["figures"]["fig4a_reward.png"] == "skipped: no attempt rewards"


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
    assert f"summary: {run.path / 'summary.json'}" in done.stdout
    assert all((run.path / "report" / name).is_file() for name in FIGURES)
