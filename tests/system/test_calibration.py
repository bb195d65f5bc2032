"""Calibration as a user runs it: a run recorded through the graph on a hidden rig, `g2p-calibrate` on its
bag, and the simulator serving the calibration it wrote (and saying so in the next bag)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from g2p.bags.dataset import load_run
from g2p.sim.calibration import LegCalibration
from tests.ros.rosproc import executable
from tests.system.test_graph import run_bringup

# The hidden rig: the model with the motors' lag this quick calibration fits changed (the model's: 0.03 s).
# How closely a calibration recovers a hidden rig, and whether its intervals hold the truth, are known
# answers of tests/identification/test_fit.py on a run recorded in process; here, the user's path.
HIDDEN = {"motor_lag_s": 0.04}


def g2p_calibrate() -> str:
    """The installed console script, beside this interpreter."""
    found = shutil.which("g2p-calibrate") or str(Path(sys.executable).with_name("g2p-calibrate"))
    assert Path(found).is_file(), "g2p-calibrate is not installed (pip install -e .[calibrate])"
    return found


@pytest.mark.slow
def test_a_hidden_rig_is_recovered_from_its_bag_and_served(tmp_path: Path) -> None:
    hidden = tmp_path / "hidden.yaml"
    hidden.write_text(LegCalibration(HIDDEN).to_yaml())
    bags = tmp_path / "bags"
    proc = run_bringup(
        tmp_path,
        *("--rig", "sim_air", "--bags-dir", str(bags), "--run-id", "hidden"),
        *("--set", f"rig.leg.calibration={hidden}"),
        *("--set", "learner.learner.babbling.duration_s=11.0", "--set", "learner.cycle.n_cycles=2"),
        *("--set", "learner.search.max_exploration_attempts=1"),
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    # The bag says which calibration ran, values and all.
    recorded = load_run(bags / "hidden").configs["/leg/sim/config"]
    assert recorded["leg"]["calibration"] == str(hidden)
    assert recorded["calibration"]["parameters"] == pytest.approx(HIDDEN)

    # A quick calibration, as a user makes one: one parameter, the Jacobian's intervals alone.
    out = tmp_path / "calibration.yaml"
    calibrate = subprocess.run(
        [
            *(g2p_calibrate(), str(bags / "hidden"), "--out", str(out)),
            *("--params", ",".join(HIDDEN), "--interval-blocks", "0"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert calibrate.returncode == 0, calibrate.stdout + calibrate.stderr
    cal = LegCalibration.load(str(out))
    assert set(cal.parameters) == set(HIDDEN) and cal.fit["interval_blocks"] == 0
    for name, truth in HIDDEN.items():
        assert cal.parameters[name] == pytest.approx(truth, rel=0.05), name
        assert 0 < cal.intervals[name] < np.inf
    assert cal.fit["held_out"] == "1 attempts"
    rmse = cal.fit["joint_angle_rmse_rad"]["held_out"]
    assert rmse["calibrated"] <= rmse["model"] / 3
    assert (tmp_path / "calibration.yaml.report" / "calibration.md").is_file()
    assert (tmp_path / "calibration.yaml.report" / "angles_held_out.png").is_file()

    # The calibrated simulated rig of the graph loads the file it wrote (from the working directory).
    proc = run_bringup(
        tmp_path,
        *("--rig", "sim_calibrated", "--bags-dir", str(bags), "--run-id", "calibrated"),
        *("--set", "learner.learner.babbling.duration_s=5.0", "--set", "learner.cycle.n_cycles=2"),
        *("--set", "learner.search.max_exploration_attempts=1"),
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    served = load_run(bags / "calibrated").configs["/leg/sim/config"]["calibration"]["parameters"]
    assert served == pytest.approx(dict(cal.parameters))
    assert np.isfinite(list(served.values())).all()


def test_the_simulator_refuses_a_bad_calibration_naming_it(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text(
        yaml.safe_dump(
            {
                "format": "g2p-leg-calibration",
                "version": 1,
                "model": "g2p_leg",
                "parameters": {"motor_lag_s": 5.0},
            }
        )
    )
    proc = subprocess.run(
        [str(executable("g2p_sim", "sim")), "--ros-args", "-p", f"leg.calibration:={bad}"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert f"leg.calibration: {bad}: motor_lag_s must be a number in [0.002, 0.2]" in proc.stderr
