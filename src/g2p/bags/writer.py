"""Writing rosbag2 bags: format version 9, MCAP storage, zstd-compressed chunks.

Built on rosbags' `Writer`. Its MCAP storage compresses chunks with zstd when the bag's compression mode
is `CompressionMode.STORAGE` (like rosbag2's mcap storage presets): metadata.yaml then says
`compression_mode: ''` because the MCAP file itself is a plain, indexed MCAP whose chunks any MCAP
reader decompresses (`ros2 bag play`, rosbags, the mcap library). On top of rosbags this module:

- writes each channel's `topic_type_hash` next to `offered_qos_profiles` in the MCAP channel metadata,
  as rosbag2's own mcap plugin does (rosbag2 reads a topic's hash from there);
- compresses each chunk into a zstd frame with a content checksum, so that readers detect a corrupted
  chunk instead of returning garbage (rosbags' default frames have no checksum);
- flushes every finished chunk to the operating system, and lets the caller close the pending chunk
  early (`close_chunk`), so that a killed recorder loses at most the chunk it was filling.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import datetime
from io import BytesIO
from pathlib import Path
from types import MappingProxyType, TracebackType
from typing import Final, cast

import numpy as np
from rosbags.interfaces import Connection, ConnectionExtRosbag2, Qos
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
from rosbags.rosbag2.storage_mcap import Channel, McapWriter, write_channel, write_string

from g2p.bags.errors import BagWriteError

if sys.version_info >= (3, 14):
    from compression import zstd
else:
    from backports import zstd

from g2p.bags.interfaces import TypeDefinition
from g2p.bags.runs import new_run_id

ROSBAG2_VERSION: Final = 9
# rosbags' MCAP storage starts a new chunk once the pending one holds this many bytes (uncompressed).
CHUNK_SIZE_BYTES = 1 << 20


@dataclass(frozen=True)
class TopicSpec:
    """A topic as a bag stores it.

    Attributes:
        name: fully qualified topic name.
        definition: the message type, its schema and its RIHS01 hash.
        offered_qos: the QoS profiles its publishers offered.
        serialization_format: encoding of the messages ("cdr" for ROS 2).
    """

    name: str
    definition: TypeDefinition
    offered_qos: tuple[Qos, ...] = ()
    serialization_format: str = "cdr"


class _McapStorage(McapWriter):
    """rosbags' MCAP storage with type hashes in channel metadata and flushed chunks."""

    def __init__(self, path: Path, compression: CompressionMode) -> None:
        super().__init__(path, compression)
        self.pending_messages = 0
        if self.compression == "zstd":
            self.compressor = _zstd_with_checksum
        self.bio.flush()  # the magic and header record: from now on the file is a valid MCAP prefix

    def add_connection(self, connection: Connection, offered_qos_profiles: str) -> None:
        metadata = BytesIO()
        for key, value in (
            ("offered_qos_profiles", offered_qos_profiles),
            ("topic_type_hash", connection.digest),
        ):
            write_string(metadata, key)
            write_string(metadata, value)
        ext = cast(ConnectionExtRosbag2, connection.ext)
        channel = Channel(
            connection.id, connection.msgtype, connection.topic, ext.serialization_format, metadata.getvalue()
        )
        self.channels.append(channel)
        self.channel_stats[connection.id] = 0
        write_channel(self.chunk.bio, channel, self.schemas)

    def write(self, connection: Connection, timestamp: int, data: bytes | memoryview) -> None:
        self.pending_messages += 1
        super().write(connection, timestamp, data)

    def close_chunk(self) -> None:
        if not self.chunk.msgs:  # only schema/channel records: give the chunk a valid time range
            t = self.message_end_time
            self.chunk.message_start_time = self.chunk.message_end_time = t
        super().close_chunk()
        self.pending_messages = 0
        self.bio.flush()


def _zstd_with_checksum(data: bytes) -> bytes:
    """A zstd frame (default level) carrying a checksum of its content."""
    return zstd.compress(data, options={zstd.CompressionParameter.checksum_flag: 1})


class _Rosbag2Writer(Writer):
    STORAGE_PLUGINS = MappingProxyType({**Writer.STORAGE_PLUGINS, StoragePlugin.MCAP: _McapStorage})


@dataclass
class _Counts:
    per_topic: dict[str, int] = field(default_factory=dict)
    total: int = 0


class BagWriter:
    """One open bag: add topics, write serialized messages, close.

    Args:
        path: the bag directory to create; it must not exist.
        custom_data: string pairs stored in metadata.yaml's custom_data.

    Raises:
        BagWriteError: the directory exists or cannot be created.
    """

    def __init__(self, path: Path | str, custom_data: Mapping[str, str] | None = None) -> None:
        self.path = Path(path)
        try:
            self._writer = _Rosbag2Writer(
                self.path, version=ROSBAG2_VERSION, storage_plugin=StoragePlugin.MCAP
            )
            self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
            for key, value in (custom_data or {}).items():
                self._writer.set_custom_data(key, value)
            self._writer.open()
        except (WriterError, OSError) as err:
            raise BagWriteError(f"cannot create the bag: {err}", self.path) from err
        self._counts = _Counts()
        self._closed = False

    @property
    def storage_path(self) -> Path:
        """The MCAP file inside the bag directory."""
        return self.path / f"{self.path.name}.mcap"

    @property
    def message_count(self) -> int:
        """Messages written so far."""
        return self._counts.total

    @property
    def topic_counts(self) -> dict[str, int]:
        """Messages written so far, per topic."""
        return dict(self._counts.per_topic)

    @property
    def closed(self) -> bool:
        """Whether the bag was closed (finalized)."""
        return self._closed

    def add_topic(self, spec: TopicSpec) -> Connection:
        """Add a topic; the returned handle is what `write` takes.

        Raises:
            BagWriteError: the bag is closed, or the topic was already added with the same type and QoS.
        """
        self._check_open()
        try:
            connection = self._writer.add_connection(
                spec.name,
                spec.definition.msgtype,
                msgdef=spec.definition.msgdef,
                rihs01=spec.definition.rihs01,
                serialization_format=spec.serialization_format,
                offered_qos_profiles=list(spec.offered_qos),
            )
        except WriterError as err:
            raise BagWriteError(f"cannot add topic {spec.name}: {err}", self.path) from err
        self._counts.per_topic.setdefault(spec.name, 0)
        return connection

    def write(self, topic: Connection, timestamp_ns: int, data: bytes | memoryview) -> None:
        """Write one serialized message.

        Args:
            topic: a handle from `add_topic`.
            timestamp_ns: the message's recording time (ns since the epoch of the recorder's clock).
            data: the message, serialized (CDR for ROS 2).

        Raises:
            BagWriteError: the bag is closed or the handle is unknown.
        """
        try:
            self._writer.write(topic, timestamp_ns, data)
        except WriterError as err:
            raise BagWriteError(f"cannot write to {topic.topic}: {err}", self.path) from err
        self._counts.per_topic[topic.topic] += 1
        self._counts.total += 1

    def close_chunk(self) -> bool:
        """Compress and write the pending chunk now, if it holds messages.

        Returns:
            Whether a chunk was written.
        """
        storage = self._writer.storage
        if self._closed or not isinstance(storage, _McapStorage) or storage.pending_messages == 0:
            return False
        storage.close_chunk()
        return True

    def close(self) -> None:
        """Write the pending chunk, the MCAP summary and metadata.yaml. Closing twice does nothing.

        Raises:
            BagWriteError: the files cannot be written.
        """
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.close()
        except (WriterError, OSError) as err:
            raise BagWriteError(f"cannot finalize the bag: {err}", self.path) from err

    def _check_open(self) -> None:
        if self._closed:
            raise BagWriteError("the bag is closed", self.path)

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


def create_run_bag(
    bags_dir: Path | str,
    now: datetime,
    rng: np.random.Generator,
    run_id: str = "",
    custom_data: Mapping[str, str] | None = None,
    attempts: int = 20,
) -> BagWriter:
    """Create the bag of a new run, `<bags_dir>/<run-id>/`.

    Args:
        bags_dir: the directory holding all runs (created if missing).
        now: the run's start time (timezone-aware), for a generated id.
        rng: source of the id's random suffix.
        run_id: use this id instead of a generated one (then it must be new).
        custom_data: extra metadata.yaml custom_data; the run id is added as "g2p.run_id".
        attempts: generated ids tried before giving up.

    Raises:
        BagWriteError: the directory cannot be created, or every id tried exists.
    """
    root = Path(bags_dir)
    ids = [run_id] if run_id else [new_run_id(now, rng) for _ in range(attempts)]
    for candidate in ids:
        path = root / candidate
        if path.exists():
            continue
        try:
            return BagWriter(path, {**(custom_data or {}), "g2p.run_id": candidate})
        except BagWriteError:
            if not path.exists():  # not a collision with another recorder: a real failure
                raise
    raise BagWriteError(f"run directory exists already (tried {', '.join(ids)})", root)
