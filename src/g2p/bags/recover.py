"""Recovering the bag of a recorder that was killed (kill -9, power loss) before it closed the bag.

A killed recorder leaves `<run>.mcap` without its summary and footer, and no metadata.yaml. Every chunk
the recorder finished is complete in the file (the writer flushes each one), so recovery reads the file
record by record, keeps the schemas, channels (with their QoS and type hash) and messages of every
complete chunk, stops at the first truncated record, and writes a new, finalized bag in place of the
old file. The old file is kept beside it as `<run>.mcap.damaged`. At most the chunk that was being
filled is lost.

    g2p-recover-bag bags/<run> [--force]

The command leaves a complete bag alone unless --force; errors give one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import shutil
import struct
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import BinaryIO, cast

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import breakup_chunk
from rosbags.rosbag2.errors import ReaderError
from rosbags.rosbag2.metadata import parse_qos
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from zstandard import ZstdError

from g2p.bags.errors import BagError, BagReadError, RecoveryError
from g2p.bags.interfaces import TypeDefinition
from g2p.bags.metadata import read_metadata
from g2p.bags.reader import BagReader
from g2p.bags.runs import METADATA_YAML
from g2p.bags.writer import BagWriter, TopicSpec

MCAP_MAGIC = b"\x89MCAP0\r\n"
_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK, _OP_DATA_END = 1, 2, 3, 4, 5, 6, 15
# What decoding a damaged chunk raises (mcap decompresses with zstandard or lz4, then parses records).
_CHUNK_ERRORS = (
    McapError,
    EOFError,
    struct.error,
    ValueError,
    UnicodeDecodeError,
    MemoryError,
    RuntimeError,
    ZstdError,
)
# A record longer than this is taken as garbage, not as data (bytes).
_MAX_RECORD_BYTES = 1 << 32


@dataclass(frozen=True)
class RecoveryResult:
    """What recovery did.

    Attributes:
        bag: the bag directory.
        recovered: False when the bag was complete and left untouched.
        message_count: messages in the recovered bag.
        topic_counts: messages per topic in the recovered bag.
        chunks: complete chunks read.
        damaged_chunks: chunks skipped because their content could not be decoded.
        orphan_messages: messages dropped because their channel record was lost.
        lost_bytes: bytes after the last complete record (the truncated tail).
        backups: the original storage files, renamed.
    """

    bag: Path
    recovered: bool
    message_count: int = 0
    topic_counts: dict[str, int] = field(default_factory=dict)
    chunks: int = 0
    damaged_chunks: int = 0
    orphan_messages: int = 0
    lost_bytes: int = 0
    backups: tuple[Path, ...] = ()


def bag_is_complete(bag: Path | str) -> bool:
    """Whether a bag has a valid metadata.yaml and storage files that open (indexed, with a footer)."""
    try:
        BagReader(bag).close()
    except BagReadError:
        return False
    return True


def recover_bag(bag: Path | str, force: bool = False) -> RecoveryResult:
    """Rebuild a readable bag (MCAP with summary, metadata.yaml) from what a killed recorder wrote.

    Args:
        bag: the bag directory.
        force: rebuild even when the bag is complete.

    Returns:
        What was recovered.

    Raises:
        RecoveryError: no MCAP file, not an MCAP file, or the new bag cannot be written.
    """
    path = Path(bag)
    if not path.is_dir():
        raise RecoveryError("not a directory", path)
    if not force and bag_is_complete(path):
        return RecoveryResult(path, recovered=False, message_count=read_metadata(path).message_count)
    sources = sorted(path.glob("*.mcap"))
    if not sources:
        raise RecoveryError("no .mcap storage file to recover", path)
    staging = path.parent / f".{path.name}.recovering"
    if staging.exists():
        shutil.rmtree(staging)
    staging.mkdir()
    try:
        rebuilt = staging / path.name
        writer = BagWriter(
            rebuilt, {"g2p.run_id": path.name, "g2p.recovered_from": ", ".join(s.name for s in sources)}
        )
        stats = _Stats()
        try:
            for source in sources:
                _copy(source, writer, stats)
        finally:
            writer.close()
        backups = tuple(_backup(f) for f in [*sources, path / METADATA_YAML] if f.exists())
        for item in rebuilt.iterdir():
            item.replace(path / item.name)
    except OSError as err:
        raise RecoveryError(f"cannot write the recovered bag: {err}", path) from err
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return RecoveryResult(
        path,
        recovered=True,
        message_count=writer.message_count,
        topic_counts=writer.topic_counts,
        chunks=stats.chunks,
        damaged_chunks=stats.damaged_chunks,
        orphan_messages=stats.orphans,
        lost_bytes=stats.lost_bytes,
        backups=backups,
    )


@dataclass
class _Stats:
    chunks: int = 0
    damaged_chunks: int = 0
    orphans: int = 0
    lost_bytes: int = 0


def recoverable_counts(bag: Path | str) -> dict[str, int]:
    """Messages per topic that recovery would keep now, read-only (also while a recorder writes the bag).

    Raises:
        RecoveryError: no MCAP file, or not an MCAP file.
    """
    path = Path(bag)
    sources = sorted(path.glob("*.mcap"))
    if not sources:
        raise RecoveryError("no .mcap storage file", path)
    counts: dict[str, int] = {}
    for source in sources:
        topics: dict[int, str] = {}
        for item in _readable(source, _Stats()):
            if isinstance(item, tuple):
                topics[item[0].id] = item[0].topic
                counts.setdefault(item[0].topic, 0)
            else:
                counts[topics[item.channel_id]] += 1
    return counts


def _copy(source: Path, writer: BagWriter, stats: _Stats) -> None:
    """Copy every readable channel and message of one MCAP file into `writer`."""
    handles = {}
    for item in _readable(source, stats):
        if isinstance(item, tuple):
            channel, schema = item
            handles[channel.id] = writer.add_topic(_topic_spec(channel, schema, source))
        else:
            writer.write(handles[item.channel_id], item.log_time, item.data)


def _readable(source: Path, stats: _Stats) -> Iterator[tuple[Channel, Schema] | Message]:
    """Each channel (with its schema) when first seen, and each message of a known channel, in file order."""
    schemas: dict[int, Schema] = {}
    channels: set[int] = set()
    with source.open("rb") as f:
        magic = f.read(len(MCAP_MAGIC))
        if len(magic) < len(MCAP_MAGIC) and MCAP_MAGIC.startswith(magic):
            return  # killed before the file's first bytes reached the disk: nothing to read
        if magic != MCAP_MAGIC:
            raise RecoveryError("not an MCAP file (bad magic)", source)
        for op, content in _records(f, source, stats):
            if op in (_OP_FOOTER, _OP_DATA_END):
                break
            if op == _OP_CHUNK:
                try:
                    records = breakup_chunk(Chunk.read(ReadDataStream(BytesIO(content))))
                except _CHUNK_ERRORS:  # the content is damaged but the framing is intact: go on after it
                    stats.damaged_chunks += 1
                    continue
                stats.chunks += 1
            elif op in (_OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE):
                records = [_read_record(op, content)]
            else:
                continue
            for record in records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif (
                    isinstance(record, Channel) and record.id not in channels and record.schema_id in schemas
                ):
                    channels.add(record.id)
                    yield record, schemas[record.schema_id]
                elif isinstance(record, Message):
                    if record.channel_id in channels:
                        yield record
                    else:
                        stats.orphans += 1


def _read_record(op: int, content: bytes) -> Schema | Channel | Message:
    """A top-level Schema, Channel or Message record from its content."""
    stream = ReadDataStream(BytesIO(content))
    if op == _OP_SCHEMA:
        return cast(Schema, Schema.read(stream))
    if op == _OP_CHANNEL:
        return cast(Channel, Channel.read(stream))
    return cast(Message, Message.read(stream, len(content)))


def _records(f: BinaryIO, source: Path, stats: _Stats) -> Iterator[tuple[int, bytes]]:
    """(opcode, content) of each complete record; stops at the first truncated or absurd one."""
    size = source.stat().st_size
    while True:
        start = f.tell()
        head = f.read(9)
        if len(head) < 9:
            stats.lost_bytes = size - start
            return
        op, length = struct.unpack("<BQ", head)
        if length > _MAX_RECORD_BYTES or start + 9 + length > size:
            stats.lost_bytes = size - start
            return
        yield op, f.read(length)


def _topic_spec(channel: Channel, schema: Schema, source: Path) -> TopicSpec:
    qos_text = channel.metadata.get("offered_qos_profiles", "")
    try:
        qos = tuple(parse_qos(qos_text)) if qos_text else ()
    except (ReaderError, KeyError, TypeError) as err:
        raise RecoveryError(
            f"channel {channel.topic}: unreadable offered_qos_profiles: {err}", source
        ) from err
    msgdef = schema.data.decode("utf-8")
    rihs01 = channel.metadata.get("topic_type_hash") or _hash_of(schema.name, msgdef, source)
    return TopicSpec(
        channel.topic, TypeDefinition(schema.name, msgdef, rihs01), qos, channel.message_encoding
    )


def _hash_of(msgtype: str, msgdef: str, source: Path) -> str:
    """The RIHS01 hash of a type from its embedded ros2msg schema (for files without topic_type_hash)."""
    store = get_typestore(Stores.EMPTY)
    try:
        store.register(get_types_from_msg(msgdef, msgtype))
        return store.hash_rihs01(msgtype)
    except Exception as err:  # rosbags' parse and hash errors have no common base class
        raise RecoveryError(f"cannot hash the schema of {msgtype}: {err}", source) from err


def _backup(file: Path) -> Path:
    """Rename `file` to `<file>.damaged` (or .damaged.N when taken) and return the new path."""
    target = file.with_name(file.name + ".damaged")
    n = 1
    while target.exists():
        target = file.with_name(f"{file.name}.damaged.{n}")
        n += 1
    file.replace(target)
    return target


def main(args: list[str] | None = None) -> None:
    """Entry point of `g2p-recover-bag`: recover one bag; exit 2 when it cannot be recovered."""
    parser = argparse.ArgumentParser(
        prog="g2p-recover-bag", description="Rebuild a readable bag from what a killed recorder wrote."
    )
    parser.add_argument("bag", type=Path, help="the bag directory (bags/<run-id>)")
    parser.add_argument("--force", action="store_true", help="rebuild even when the bag is complete")
    ns = parser.parse_args(sys.argv[1:] if args is None else args)
    try:
        result = recover_bag(ns.bag, force=ns.force)
    except BagError as err:
        print(f"g2p-recover-bag: error: {err}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        sys.exit(130)
    if not result.recovered:
        print(f"{result.bag}: complete, nothing to recover ({result.message_count} messages)")
        return
    print(
        f"{result.bag}: recovered {result.message_count} messages on {len(result.topic_counts)} topics from "
        f"{result.chunks} complete chunks"
    )
    for topic, count in sorted(result.topic_counts.items()):
        print(f"  {topic}: {count}")
    if result.damaged_chunks or result.orphan_messages:
        print(
            f"  skipped {result.damaged_chunks} damaged chunks and "
            f"{result.orphan_messages} messages without a channel"
        )
    print(
        f"  truncated tail: {result.lost_bytes} bytes; original kept as "
        f"{', '.join(str(b) for b in result.backups)}"
    )


if __name__ == "__main__":
    main()
