"""The `two_host_bench` fixture: a fresh TwoHostBench per test, skipped where benches cannot be built."""

from __future__ import annotations

import functools
from collections.abc import Iterator

import pytest

from tests.twohost.bench import TwoHostBench, available

_available = functools.cache(available)  # the answer does not change during a session


@pytest.fixture
def two_host_bench() -> Iterator[TwoHostBench]:
    """A rig and a workstation namespace joined by a clean TUN link, torn down after the test."""
    reason = _available()
    if reason is not None:
        pytest.skip(reason)
    with TwoHostBench() as bench:
        yield bench
