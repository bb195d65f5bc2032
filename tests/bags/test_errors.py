"""A corrupted or truncated bag gives a BagReadError naming the file; the CLIs print one line and exit 2."""

from __future__ import annotations

import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest

from g2p.bags import BagError, BagReader, BagReadError, load_run, read_metadata
from tests.bags.bagdata import SyntheticRun
from tests.commands import console_script


@pytest.fixture
def bag(synthetic_run: Callable[..., SyntheticRun]) -> Path:
    return synthetic_run().path


def mcap_of(bag: Path) -> Path:
    return bag / f"{bag.name}.mcap"


def read_everything(bag: Path) -> int:
    with BagReader(bag) as reader:
        return sum(1 for _ in reader.messages())


def test_intact_bag_reads(bag: Path) -> None:
    assert read_everything(bag) == read_metadata(bag).message_count


def test_truncated_mcap_names_the_file(bag: Path) -> None:
    mcap = mcap_of(bag)
    with mcap.open("r+b") as f:
        f.truncate(mcap.stat().st_size // 2)
    with pytest.raises(BagReadError) as info:
        read_everything(bag)
    assert info.value.path == mcap
    assert str(info.value).startswith(f"{mcap}: ")


def test_corrupted_chunk_names_the_file(bag: Path) -> None:
    mcap = mcap_of(bag)
    data = bytearray(mcap.read_bytes())
    data[2000:6000] = b"\xff" * 4000  # inside the first chunk's compressed data
    mcap.write_bytes(bytes(data))
    with pytest.raises(BagReadError) as info:
        read_everything(bag)
    assert info.value.path == mcap


def test_bad_magic_names_the_file(bag: Path) -> None:
    mcap = mcap_of(bag)
    data = bytearray(mcap.read_bytes())
    data[:8] = b"NOTMCAP!"
    mcap.write_bytes(bytes(data))
    with pytest.raises(BagReadError) as info:
        read_everything(bag)
    assert info.value.path == mcap


def test_missing_metadata_points_to_recovery(bag: Path) -> None:
    (bag / "metadata.yaml").unlink()
    with pytest.raises(BagReadError, match=r"metadata.yaml: missing .*recover_bag") as info:
        BagReader(bag)
    assert info.value.path == bag / "metadata.yaml"


@pytest.mark.parametrize(
    "text, why",
    [("{not yaml: [", "cannot read"), ("rosbag2_bagfile_information: {version: 9}", "fields missing")],
)
def test_invalid_metadata_names_the_file(bag: Path, text: str, why: str) -> None:
    (bag / "metadata.yaml").write_text(text)
    with pytest.raises(BagReadError, match=why) as info:
        read_metadata(bag)
    assert info.value.path == bag / "metadata.yaml"


def test_missing_storage_file(bag: Path) -> None:
    mcap_of(bag).unlink()
    with pytest.raises(BagReadError, match=r"storage file listed in metadata\.yaml is missing"):
        BagReader(bag)


def test_not_a_bag(tmp_path: Path) -> None:
    with pytest.raises(BagReadError, match="not a bag directory"):
        load_run(tmp_path / "nowhere")


def test_load_run_of_a_truncated_bag(bag: Path) -> None:
    with mcap_of(bag).open("r+b") as f:
        f.truncate(1000)
    with pytest.raises(BagError):
        load_run(bag)


def test_report_cli_one_line_and_exit_2(bag: Path) -> None:
    mcap = mcap_of(bag)
    with mcap.open("r+b") as f:
        f.truncate(mcap.stat().st_size // 2)
    done = subprocess.run(
        [str(console_script("g2p-report")), str(bag)], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 2
    lines = done.stderr.splitlines()
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith(f"g2p-report: error: {mcap}: ")
    assert "Traceback" not in done.stderr and not (bag / "summary.json").exists()
