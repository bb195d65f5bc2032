"""Atomic file writes (reports, sweep tables): a reader sees the old file or the new one, never half."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path

# Written files are for anyone to open; mkstemp would leave them private (0600).
_FILE_MODE = 0o644


def write_atomically(path: Path, render: Callable[[Path], None]) -> Path:
    """Have `render` write a temporary file beside `path`, then rename it over `path`.

    The temporary file is in the same directory (so the rename is atomic) and keeps the suffix of
    `path` (writers that pick the format by suffix still do). If `render` raises, the temporary file
    is removed, an existing `path` is left as it was, and the exception propagates.

    Args:
        path: the file to write; its directory is created when missing.
        render: writes the whole file to the path it is given.

    Returns:
        `path`.

    Raises:
        OSError: the directory or the temporary file cannot be created, or the rename fails.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}", dir=path.parent)
    os.close(fd)
    tmp = Path(name)
    try:
        render(tmp)
        os.chmod(tmp, _FILE_MODE)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def write_text_atomically(path: Path, text: str) -> Path:
    """Write `text` (UTF-8) to `path` atomically (see write_atomically)."""

    def render(tmp: Path) -> None:
        tmp.write_text(text, encoding="utf-8")

    return write_atomically(path, render)
