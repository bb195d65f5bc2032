"""bringup starts its nodes with the graph's Fast DDS profile, which Fast DDS accepts."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from g2p_ros.bringup_main import _node_environment

PROFILE_VARIABLE = "FASTDDS_DEFAULT_PROFILES_FILE"


def test_the_profile_is_set_unless_the_user_set_one(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(PROFILE_VARIABLE, raising=False)
    profile = Path(_node_environment()[PROFILE_VARIABLE])
    assert profile.name == "fastdds_discovery.xml" and profile.is_file()
    monkeypatch.setenv(PROFILE_VARIABLE, "/elsewhere/profiles.xml")
    assert _node_environment()[PROFILE_VARIABLE] == "/elsewhere/profiles.xml"


def test_fast_dds_loads_the_profile_without_errors(monkeypatch: pytest.MonkeyPatch) -> None:
    """A node started with the profile comes up, and Fast DDS reports no XML error."""
    monkeypatch.delenv(PROFILE_VARIABLE, raising=False)
    code = "import rclpy; rclpy.init(); rclpy.create_node('profile_probe').destroy_node(); rclpy.shutdown()"
    proc = subprocess.run(
        [sys.executable, "-c", code], env=_node_environment(), capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 0, proc.stderr
    assert "XMLPARSER" not in proc.stderr and "Error" not in proc.stderr, proc.stderr
    # The same check catches a broken profile: Fast DDS reports it on stderr.
    broken = dict(_node_environment(), **{PROFILE_VARIABLE: os.devnull})
    proc = subprocess.run(
        [sys.executable, "-c", code], env=broken, capture_output=True, text=True, timeout=60
    )
    assert "XMLPARSER" in proc.stderr
