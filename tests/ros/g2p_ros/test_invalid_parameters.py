"""Every node executable refuses an invalid or wrongly typed parameter, and an override naming no parameter
it has: exit code 2, the parameter named (with the nearest names it has, for a misspelt one).

A node whose construction fails is still destroyed by rclpy's shutdown; its teardown must not turn the
message into a traceback.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from tests.ros.rosproc import executable


def run_with(package: str, name: str, parameter: str, tmp_path: Path) -> subprocess.CompletedProcess[str]:
    """Run the executable with one parameter override (the recorder writing into `tmp_path`) to its end."""
    args = ["--ros-args", "-p", parameter]
    if name == "record":
        args += ["-p", f"bags_dir:={tmp_path}"]
    return subprocess.run(
        [str(executable(package, name)), *args], capture_output=True, text=True, timeout=60, cwd=tmp_path
    )


@pytest.mark.parametrize(
    ("package", "name", "parameter", "expected"),
    [
        ("g2p_sim", "sim", "rig.clock_period_ticks:=0", "rig.clock_period_ticks: must be >= 1"),
        ("g2p_sim", "sim", "leg.tick_hz:=78", "leg.tick_hz: wrong type (a float needs its decimal point"),
        ("g2p_driver", "driver", "rig.clock_period_ticks:=0", "rig.clock_period_ticks: must be >= 1"),
        ("g2p_driver", "driver", "description_file:=/nonexistent/leg.urdf", "description_file: [Errno 2]"),
        ("g2p_recorder", "record", "run_id:=a/b", "run_id: must be a plain directory name"),
        ("g2p_learner", "learn", "rig_timeout_s:=-1.0", "rig_timeout_s: must be a finite number > 0"),
        ("g2p_learner", "learn", "search.threshold_mm:=64", "search.threshold_mm: wrong type"),
    ],
)
def test_invalid_parameter_exits_2_naming_it(
    package: str, name: str, parameter: str, expected: str, tmp_path: Path
) -> None:
    done = run_with(package, name, parameter, tmp_path)
    assert done.returncode == 2, done.stderr
    assert expected in done.stderr
    assert "Traceback" not in done.stderr
    assert list(tmp_path.iterdir()) == []  # the recorder created no bag


@pytest.mark.parametrize(
    ("package", "name", "parameter", "expected"),
    [
        (
            "g2p_sim",
            "sim",
            "leg.tick_hzz:=78.0",
            "g2p_sim: invalid parameter leg.tick_hzz: not a parameter of /leg/sim (nearest: leg.tick_hz",
        ),
        (
            "g2p_learner",
            "learn",
            "search.treshold_mm:=64.0",
            "learn: invalid parameter search.treshold_mm: not a parameter of /leg/learner "
            "(nearest: search.threshold_mm",
        ),
        (
            "g2p_recorder",
            "record",
            "bag_dir:=bags",
            "record: invalid parameter bag_dir: not a parameter of /recorder (nearest: bags_dir",
        ),
        (
            "g2p_driver",
            "driver",
            "autostrat:=true",
            "g2p_driver: invalid parameter autostrat: not a parameter of /leg/driver (nearest: autostart",
        ),
    ],
)
def test_an_override_naming_no_parameter_exits_2_naming_it_and_the_nearest(
    package: str, name: str, parameter: str, expected: str, tmp_path: Path
) -> None:
    """rclpy would ignore it without a word: the node would run with the default the user meant to change."""
    done = run_with(package, name, parameter, tmp_path)
    assert done.returncode == 2, done.stderr
    assert expected in done.stderr
    assert "Traceback" not in done.stderr
    assert list(tmp_path.iterdir()) == []  # the recorder created no bag, under either name
