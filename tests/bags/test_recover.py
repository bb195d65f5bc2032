"""Recovery of a killed recorder's bag: every complete chunk comes back, at most the last one is lost."""

from __future__ import annotations

import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest

from g2p.bags import (
    BagReader,
    BagWriter,
    RecoveryError,
    TopicSpec,
    TypeRegistry,
    bag_is_complete,
    recover_bag,
)
from tests.bags.bagdata import SAMPLE_QOS, Messages
from tests.commands import console_script

CHUNKS = 3
PER_CHUNK = 1000


def payloads(messages: Messages, n: int) -> list[tuple[str, int, bytes]]:
    out = []
    for k in range(n):
        t = 7_000_000_000 + 1_000_000 * k
        out.append(
            (
                "/leg/treadmill",
                t,
                messages.cdr(
                    messages.make(
                        "g2p_interfaces/msg/Treadmill",
                        header=messages.header(t),
                        displacement_mm=float(k),
                        velocity_mm_s=2.0,
                    )
                ),
            )
        )
        out.append(
            (
                "/leg/applied_activation",
                t + 1,
                messages.cdr(
                    messages.make(
                        "g2p_interfaces/msg/MotorActivation",
                        header=messages.header(t),
                        activation=np.array([0.15, 0.2, k / 3000]),
                    )
                ),
            )
        )
    return out


def crashed_bag(
    tmp_path: Path, registry: TypeRegistry, messages: Messages, pending: int = 500
) -> tuple[Path, list[tuple[str, int, bytes]], Path]:
    """A bag as kill -9 leaves it: CHUNKS finished chunks, `pending` ticks never written, no metadata.yaml.

    Returns the crashed copy, the messages of the finished chunks, and the finalized original.
    """
    original = tmp_path / "original"
    msgs = payloads(messages, CHUNKS * PER_CHUNK + pending)
    writer = BagWriter(original)
    handles = {
        t: writer.add_topic(TopicSpec(t, registry.definition(m), (SAMPLE_QOS,)))
        for t, m in (
            ("/leg/treadmill", "g2p_interfaces/msg/Treadmill"),
            ("/leg/applied_activation", "g2p_interfaces/msg/MotorActivation"),
        )
    }
    for i, (topic, t, data) in enumerate(msgs, start=1):
        writer.write(handles[topic], t, data)
        if i % (2 * PER_CHUNK) == 0 and i <= 2 * CHUNKS * PER_CHUNK:
            assert writer.close_chunk()
    crashed = tmp_path / "20261121T120000Z-abcdef"
    shutil.copytree(original, crashed)  # what is on disk at the moment of the kill
    writer.close()
    return crashed, msgs[: 2 * CHUNKS * PER_CHUNK], original


def read_all(path: Path) -> list[tuple[str, int, bytes]]:
    with BagReader(path) as reader:
        return [(m.topic, m.timestamp_ns, m.data) for m in reader.raw_messages()]


def chunk_offsets(mcap: Path) -> list[tuple[int, int]]:
    """(start, end) byte offsets of the chunk records of an MCAP file."""
    data = mcap.read_bytes()
    pos, chunks = 8, []
    while pos + 9 <= len(data):
        op, length = struct.unpack_from("<BQ", data, pos)
        if op == 0x06:
            chunks.append((pos, pos + 9 + length))
        if op == 0x0F:  # data end
            break
        pos += 9 + length
    return chunks


def test_crashed_bag_is_not_readable(tmp_path: Path, registry: TypeRegistry, messages: Messages) -> None:
    crashed, _, _ = crashed_bag(tmp_path, registry, messages)
    assert not (crashed / "metadata.yaml").exists()
    assert not bag_is_complete(crashed)


def test_recovers_every_finished_chunk(tmp_path: Path, registry: TypeRegistry, messages: Messages) -> None:
    crashed, kept, original = crashed_bag(tmp_path, registry, messages)
    result = recover_bag(crashed)
    assert result.recovered
    assert result.chunks == CHUNKS and result.damaged_chunks == 0 and result.orphan_messages == 0
    assert result.message_count == len(kept)
    assert read_all(crashed) == kept
    assert bag_is_complete(crashed)
    # topics keep their type, hash and QoS
    with BagReader(crashed) as recovered, BagReader(original) as complete:
        assert {n: (t.msgtype, t.type_hash, t.offered_qos) for n, t in recovered.topics.items()} == {
            n: (t.msgtype, t.type_hash, t.offered_qos) for n, t in complete.topics.items()
        }
    assert [p.name for p in result.backups] == ["original.mcap.damaged"]
    assert sorted(p.name for p in crashed.iterdir()) == [
        crashed.name + ".mcap",
        "metadata.yaml",
        "original.mcap.damaged",
    ]


def test_truncated_chunk_is_lost_alone(tmp_path: Path, registry: TypeRegistry, messages: Messages) -> None:
    crashed, kept, _ = crashed_bag(tmp_path, registry, messages)
    mcap = crashed / "original.mcap"
    chunks = chunk_offsets(mcap)
    assert len(chunks) == CHUNKS
    start, end = chunks[-1]
    with mcap.open("r+b") as f:
        f.truncate((start + end) // 2)  # killed while the last chunk was being written
    result = recover_bag(crashed)
    assert result.chunks == CHUNKS - 1
    assert result.lost_bytes == (start + end) // 2 - start
    assert read_all(crashed) == kept[: 2 * (CHUNKS - 1) * PER_CHUNK]


def test_damaged_chunk_in_the_middle_is_skipped(
    tmp_path: Path, registry: TypeRegistry, messages: Messages
) -> None:
    crashed, kept, _ = crashed_bag(tmp_path, registry, messages)
    mcap = crashed / "original.mcap"
    start, end = chunk_offsets(mcap)[1]
    data = bytearray(mcap.read_bytes())
    middle = (start + end) // 2
    data[middle : middle + 64] = b"\xff" * 64
    mcap.write_bytes(bytes(data))
    result = recover_bag(crashed)
    assert result.damaged_chunks == 1 and result.chunks == CHUNKS - 1
    n = 2 * PER_CHUNK
    assert read_all(crashed) == kept[:n] + kept[2 * n :]


def test_complete_bag_is_left_alone(tmp_path: Path, registry: TypeRegistry, messages: Messages) -> None:
    _, _, original = crashed_bag(tmp_path, registry, messages)
    before = {p.name: p.read_bytes() for p in original.iterdir()}
    result = recover_bag(original)
    assert not result.recovered
    assert {p.name: p.read_bytes() for p in original.iterdir()} == before


def test_forced_rebuild_of_a_complete_bag_keeps_every_message(
    tmp_path: Path, registry: TypeRegistry, messages: Messages
) -> None:
    _, _, original = crashed_bag(tmp_path, registry, messages)
    before = read_all(original)
    assert recover_bag(original, force=True).recovered
    assert read_all(original) == before


def test_not_an_mcap_file(tmp_path: Path) -> None:
    bag = tmp_path / "run"
    bag.mkdir()
    (bag / "run.mcap").write_bytes(b"this is not mcap at all")
    with pytest.raises(RecoveryError, match=r"run\.mcap: not an MCAP file"):
        recover_bag(bag)


def test_no_storage_file(tmp_path: Path) -> None:
    with pytest.raises(RecoveryError, match=r"no \.mcap storage file"):
        recover_bag(tmp_path)


def test_cli_recovers_and_reports(tmp_path: Path, registry: TypeRegistry, messages: Messages) -> None:
    crashed, kept, _ = crashed_bag(tmp_path, registry, messages)
    done = subprocess.run(
        [str(console_script("g2p-recover-bag")), str(crashed)], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    assert f"recovered {len(kept)} messages on 2 topics from {CHUNKS} complete chunks" in done.stdout
    again = subprocess.run(
        [str(console_script("g2p-recover-bag")), str(crashed)], capture_output=True, text=True, timeout=60
    )
    assert again.returncode == 0 and "complete, nothing to recover" in again.stdout


def test_cli_error_is_one_line_and_exit_2(tmp_path: Path) -> None:
    done = subprocess.run(
        [str(console_script("g2p-recover-bag")), str(tmp_path / "nope")],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2
    assert done.stderr.splitlines() == [f"g2p-recover-bag: error: {tmp_path / 'nope'}: not a directory"]
