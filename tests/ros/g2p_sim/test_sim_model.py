"""The installed `sim` executable refuses a leg model of the user's own that lacks what the plant reads."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

from g2p.sim import packaged_model_path
from g2p.sim.limits import NUMERICS
from tests.ros.rosproc import executable


def test_a_model_written_before_the_limits_exits_2_naming_the_file_and_every_missing_numeric(
    tmp_path: Path,
) -> None:
    # The packaged model less the limits' numerics: a model written before the limits existed.
    packaged = packaged_model_path().read_text()
    names = "|".join(NUMERICS.values())
    lines = re.findall(rf'<numeric name="(?:{names})" data="[^"]*"/>', packaged)
    assert len(lines) == len(NUMERICS)
    mine = tmp_path / "my_leg.xml"
    mine.write_text(re.sub(rf'\s*<numeric name="(?:{names})"[^\n]*', "", packaged))
    proc = subprocess.run(
        [str(executable("g2p_sim", "sim")), "--ros-args", "-p", f"leg.model_path:={mine}"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr
    missing = ", ".join(NUMERICS.values())
    expected = f"invalid parameter leg.model_path: {mine}: model lacks the custom numerics {missing};"
    assert expected in proc.stderr
    assert all(line in proc.stderr for line in lines)  # the packaged values, to copy
