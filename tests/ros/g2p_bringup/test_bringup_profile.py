"""bringup starts its nodes with the graph's Fast DDS profile, which Fast DDS (2.x on Jazzy, 3.x on Kilted)
reads and accepts."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from g2p_bringup.bringup import _node_environment
from g2p_bringup.dds import PROFILE_VARIABLES, profile_variable, two_host_environment

PROBE = "import rclpy; rclpy.init(); rclpy.create_node('profile_probe').destroy_node(); rclpy.shutdown()"


def _probe(env: dict[str, str]) -> str:
    """What a node's start in `env` prints (Fast DDS 2.x reports XML errors on stdout, 3.x on stderr)."""
    proc = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout + proc.stderr


@pytest.fixture
def no_user_profile(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in PROFILE_VARIABLES:
        monkeypatch.delenv(name, raising=False)


@pytest.mark.usefixtures("no_user_profile")
def test_the_profile_is_set_in_the_installed_fast_dds_variable_unless_the_user_set_one(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    env = _node_environment(tmp_path)
    assert [name for name in PROFILE_VARIABLES if name in env] == [profile_variable()]
    profile = Path(env[profile_variable()])
    assert profile.name == "fastdds_discovery.xml" and profile.is_file()
    assert "@" not in profile.read_text()  # every placeholder filled in
    for name in PROFILE_VARIABLES:  # a user's file under either name is kept, and nothing is added
        monkeypatch.setenv(name, "/elsewhere/profiles.xml")
        env = _node_environment(tmp_path)
        assert [n for n in PROFILE_VARIABLES if n in env] == [name]
        assert env[name] == "/elsewhere/profiles.xml"
        monkeypatch.delenv(name)


@pytest.mark.usefixtures("no_user_profile")
def test_fast_dds_loads_the_profile_without_errors(tmp_path: Path) -> None:
    """A node started with the profile comes up, and Fast DDS reports no XML error or warning."""
    output = _probe(_node_environment(tmp_path))
    assert "XMLPARSER" not in output and "Error" not in output and "WARN" not in output, output
    # The same check catches a broken profile: the file is really read on this distribution.
    broken = dict(_node_environment(tmp_path), **{profile_variable(): os.devnull})
    assert "XMLPARSER" in _probe(broken)


def test_fast_dds_loads_the_two_host_profile_without_errors(tmp_path: Path) -> None:
    """The UDP-only profile of a two-host graph (here for loopback's address) loads on this distribution."""
    env = two_host_environment(
        dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST"), "127.0.0.1", tmp_path
    )
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"  # this test stays on loopback
    assert [name for name in PROFILE_VARIABLES if name in env] == [profile_variable()]
    output = _probe(env)
    assert "XMLPARSER" not in output and "Error" not in output and "WARN" not in output, output
