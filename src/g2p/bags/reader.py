"""Reading bags: metadata, raw and decoded messages in time order, with errors that name the file.

Decoding uses the schemas embedded in the bag (through rosbags' AnyReader), so a bag can be read on a
machine without the message packages installed.
"""

from __future__ import annotations

import struct
import sys
from collections.abc import Collection, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.interfaces import Connection
from rosbags.rosbag2.errors import ReaderError

if sys.version_info >= (3, 14):
    from compression.zstd import ZstdError
else:
    from backports.zstd import ZstdError

from g2p.bags.errors import BagReadError
from g2p.bags.metadata import BagMetadata, TopicInfo, read_metadata

# What rosbags and the decompressors raise on damaged data (besides their own error classes).
_DATA_ERRORS = (
    AnyReaderError,
    ReaderError,
    EOFError,
    OSError,
    struct.error,
    IndexError,
    KeyError,
    ValueError,
    UnicodeDecodeError,
    AssertionError,
    MemoryError,
    ZstdError,
    RuntimeError,
)


@dataclass(frozen=True)
class RawMessage:
    """A message as stored.

    Attributes:
        topic: topic name.
        msgtype: message type.
        timestamp_ns: recording time (ns).
        data: serialized message (CDR).
    """

    topic: str
    msgtype: str
    timestamp_ns: int
    data: bytes


@dataclass(frozen=True)
class DecodedMessage:
    """A decoded message: `msg` has the message's fields as attributes (rosbags' dataclasses).

    Attributes:
        topic: topic name.
        msgtype: message type.
        timestamp_ns: recording time (ns).
        msg: the message.
    """

    topic: str
    msgtype: str
    timestamp_ns: int
    msg: Any


class BagReader:
    """An open bag (rosbag2 directory with metadata.yaml).

    Args:
        path: the bag directory.

    Raises:
        BagReadError: the bag is missing, truncated or corrupted (the message names the file).
    """

    def __init__(self, path: Path | str) -> None:
        self.path = Path(path)
        self.metadata: BagMetadata = read_metadata(self.path)
        files = self.metadata.storage_files
        for file in files:
            if not file.is_file():
                raise BagReadError("storage file listed in metadata.yaml is missing", file)
        self._file = files[0] if files else self.metadata.path
        try:
            self._reader = AnyReader([self.path])
            self._reader.open()
        except (*_DATA_ERRORS, FileNotFoundError) as err:
            raise BagReadError(f"cannot open: {_describe(err)}", self._file) from err
        self._connections: dict[str, list[Connection]] = {}
        for connection in self._reader.connections:
            self._connections.setdefault(connection.topic, []).append(connection)

    @property
    def topics(self) -> dict[str, TopicInfo]:
        """The bag's topics by name (from metadata.yaml)."""
        return self.metadata.topics

    @property
    def start_ns(self) -> int:
        """Timestamp of the first message (ns)."""
        return self.metadata.starting_time_ns

    @property
    def duration_ns(self) -> int:
        """Last minus first message timestamp (ns)."""
        return self.metadata.duration_ns

    def raw_messages(self, topics: Collection[str] = ()) -> Iterator[RawMessage]:
        """The messages of `topics` (all when empty), serialized, in timestamp order.

        Raises:
            BagReadError: a chunk or message cannot be read (the message names the file).
        """
        unknown = [t for t in topics if t not in self._connections]
        if unknown:
            raise BagReadError(f"no such topic(s) in the bag: {', '.join(unknown)}", self.path)
        connections = [c for t in topics for c in self._connections[t]]
        try:
            for connection, timestamp, data in self._reader.messages(connections=connections):
                yield RawMessage(connection.topic, connection.msgtype, timestamp, bytes(data))
        except _DATA_ERRORS as err:
            raise BagReadError(f"damaged data: {_describe(err)}", self._file) from err

    def messages(self, topics: Collection[str] = ()) -> Iterator[DecodedMessage]:
        """The messages of `topics` (all when empty), decoded, in timestamp order.

        Raises:
            BagReadError: a chunk or message cannot be read or decoded (the message names the file).
        """
        for raw in self.raw_messages(topics):
            try:
                msg = self._reader.deserialize(raw.data, raw.msgtype)
            except _DATA_ERRORS as err:
                raise BagReadError(
                    f"cannot decode a {raw.msgtype} message on {raw.topic} at "
                    f"{raw.timestamp_ns} ns: {_describe(err)}",
                    self._file,
                ) from err
            yield DecodedMessage(raw.topic, raw.msgtype, raw.timestamp_ns, msg)

    def close(self) -> None:
        """Close the storage files."""
        if self._reader.stack is not None:
            self._reader.close()

    def __enter__(self) -> BagReader:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


def _describe(err: BaseException) -> str:
    text = str(err).strip().splitlines()[0] if str(err).strip() else ""
    return f"{type(err).__name__}: {text}" if text else type(err).__name__
