"""Fixtures of the node tests: the simulator in fast mode, and a peer node to drive and watch it."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.ros.rig_nodes import FAST_SIM_SEED, RigPeer, start_sim
from tests.ros.rosproc import NodeProcess


@pytest.fixture
def fast_sim(tmp_path: Path) -> Iterator[NodeProcess]:
    """`ros2 run g2p_sim sim` in fast mode, leg seed FAST_SIM_SEED, logging into the test's directory."""
    proc = start_sim(tmp_path, "time_mode:=fast", f"leg.seed:={FAST_SIM_SEED}")
    yield proc
    assert proc.stop() == 0, proc.log()


@pytest.fixture
def peer() -> Iterator[RigPeer]:
    """A peer node subscribed to the rig's topics, with its action and reset clients."""
    p = RigPeer()
    yield p
    p.close()


@pytest.fixture
def client_peer() -> Iterator[RigPeer]:
    """A peer node that also drives the rig with a `RigClient` (`peer.client`)."""
    p = RigPeer(rig_client=True)
    yield p
    p.close()
