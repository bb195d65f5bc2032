"""The core package's console scripts (`[project.scripts]` in pyproject.toml), as a user runs them."""

from __future__ import annotations

import sys
from pathlib import Path


def console_script(name: str) -> Path:
    """The installed console script `name` (e.g. g2p-report) of this Python environment."""
    path = Path(sys.executable).with_name(name)
    assert path.is_file(), f"{path} is not installed (run scripts/bootstrap)"
    return path
