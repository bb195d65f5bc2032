"""Every node executable refuses an invalid or wrongly typed parameter: exit code 2, the parameter named.

A node whose construction fails is still destroyed by rclpy's shutdown; its teardown must not turn the
message into a traceback.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from tests.ros.rosproc import executable


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
    done = subprocess.run(
        [str(executable(package, name)), "--ros-args", "-p", parameter, "-p", f"bags_dir:={tmp_path}"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2, done.stderr
    assert expected in done.stderr
    assert "Traceback" not in done.stderr
    assert list(tmp_path.iterdir()) == []  # the recorder created no bag
