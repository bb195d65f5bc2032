"""The error hierarchy of `g2p.bags`: every failure names the file or directory it is about."""

from __future__ import annotations

from pathlib import Path


class BagError(Exception):
    """Base class of every error raised by `g2p.bags`.

    Attributes:
        path: the bag directory or file the error is about (None when not about a file).
        reason: what went wrong, without the path.
    """

    def __init__(self, reason: str, path: Path | str | None = None) -> None:
        self.path = Path(path) if path is not None else None
        self.reason = reason
        super().__init__(f"{self.path}: {reason}" if self.path is not None else reason)


class BagReadError(BagError):
    """A bag is missing, truncated or corrupted, or its metadata is invalid."""


class BagWriteError(BagError):
    """A bag cannot be created or written."""


class RecoveryError(BagError):
    """A bag cannot be recovered (no storage file, not MCAP, nothing readable)."""


class InterfaceError(BagError):
    """A message definition cannot be found in the installed interfaces, or cannot be parsed."""
