"""Fixtures for the bag tests: the installed message types and a synthetic learning run (see bagdata.py)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from g2p.bags import InterfaceLibrary, TypeRegistry, ament_share_dirs
from tests.bags.bagdata import Messages, SyntheticRun, write_synthetic_run


@pytest.fixture(scope="session")
def registry() -> TypeRegistry:
    return TypeRegistry(InterfaceLibrary(ament_share_dirs()))


@pytest.fixture(scope="session")
def messages(registry: TypeRegistry) -> Messages:
    return Messages(registry)


@pytest.fixture
def synthetic_run(tmp_path: Path, messages: Messages) -> Callable[..., SyntheticRun]:
    def make(name: str = "20261121T120000Z-abcdef", **kwargs: Any) -> SyntheticRun:
        return write_synthetic_run(tmp_path / name, messages, **kwargs)

    return make
