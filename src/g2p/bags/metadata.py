"""metadata.yaml of a rosbag2 bag (format version 9): reading and checking the fields rosbag2 requires."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml
from rosbags.interfaces import Qos
from rosbags.rosbag2.errors import ReaderError
from rosbags.rosbag2.metadata import parse_qos

from g2p.bags.errors import BagReadError
from g2p.bags.runs import METADATA_YAML

# Keys rosbag2 (version 9) reads from rosbag2_bagfile_information, and from each topic's topic_metadata.
REQUIRED_KEYS = (
    "version",
    "storage_identifier",
    "duration",
    "starting_time",
    "message_count",
    "topics_with_message_count",
    "compression_format",
    "compression_mode",
    "relative_file_paths",
    "files",
    "custom_data",
    "ros_distro",
)
REQUIRED_TOPIC_KEYS = (
    "name",
    "type",
    "serialization_format",
    "offered_qos_profiles",
    "type_description_hash",
)


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a bag.

    Attributes:
        name: fully qualified topic name.
        msgtype: message type, "package/msg/Name".
        serialization_format: message encoding ("cdr").
        offered_qos: the recorded publishers' offered QoS profiles.
        type_hash: RIHS01 type description hash ("" when the bag has none).
        message_count: messages of this topic in the bag.
    """

    name: str
    msgtype: str
    serialization_format: str
    offered_qos: tuple[Qos, ...]
    type_hash: str
    message_count: int


@dataclass(frozen=True)
class BagMetadata:
    """The content of a bag's metadata.yaml.

    Attributes:
        path: the metadata.yaml file.
        version: rosbag2 metadata format version.
        storage_identifier: storage plugin ("mcap").
        relative_file_paths: storage files, relative to the bag directory.
        starting_time_ns: timestamp of the first message (ns).
        duration_ns: last minus first message timestamp (ns).
        message_count: messages in the bag.
        topics: the topics by name.
        compression_format: whole-file or per-message compression ("" for none: MCAP chunk compression
            does not show here).
        compression_mode: "", "file" or "message".
        custom_data: free string pairs.
        ros_distro: the distribution (or tool) that wrote the bag.
    """

    path: Path
    version: int
    storage_identifier: str
    relative_file_paths: tuple[str, ...]
    starting_time_ns: int
    duration_ns: int
    message_count: int
    topics: dict[str, TopicInfo]
    compression_format: str
    compression_mode: str
    custom_data: dict[str, str]
    ros_distro: str

    @property
    def storage_files(self) -> list[Path]:
        """The storage files, as paths."""
        return [self.path.parent / p for p in self.relative_file_paths]


def read_metadata(bag: Path | str) -> BagMetadata:
    """Read and check a bag's metadata.yaml.

    Args:
        bag: the bag directory.

    Raises:
        BagReadError: the file is missing, is not YAML, or lacks a field rosbag2 requires (the error
            names the file).
    """
    path = Path(bag) / METADATA_YAML
    if not Path(bag).is_dir():
        raise BagReadError("not a bag directory", bag)
    try:
        document = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError as err:
        raise BagReadError(
            "missing (the recorder did not finish: try `recover_bag` on the bag directory)", path
        ) from err
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as err:
        raise BagReadError(f"cannot read: {err}", path) from err
    try:
        return _parse(path, document)
    except (KeyError, TypeError, ValueError, ReaderError) as err:
        raise BagReadError(f"invalid rosbag2 metadata: {type(err).__name__}: {err}", path) from err


def _parse(path: Path, document: Any) -> BagMetadata:
    info = document["rosbag2_bagfile_information"]
    missing = [k for k in REQUIRED_KEYS if k not in info]
    if missing:
        raise KeyError(f"fields missing: {', '.join(missing)}")
    topics = {}
    for entry in info["topics_with_message_count"]:
        meta = entry["topic_metadata"]
        absent = [k for k in REQUIRED_TOPIC_KEYS if k not in meta]
        if absent:
            raise KeyError(f"topic {meta.get('name')!r} lacks {', '.join(absent)}")
        topics[meta["name"]] = TopicInfo(
            name=meta["name"],
            msgtype=meta["type"],
            serialization_format=meta["serialization_format"],
            offered_qos=tuple(parse_qos(meta["offered_qos_profiles"])),
            type_hash=meta["type_description_hash"] or "",
            message_count=int(entry["message_count"]),
        )
    return BagMetadata(
        path=path,
        version=int(info["version"]),
        storage_identifier=str(info["storage_identifier"]),
        relative_file_paths=tuple(str(p) for p in info["relative_file_paths"]),
        starting_time_ns=int(info["starting_time"]["nanoseconds_since_epoch"]),
        duration_ns=int(info["duration"]["nanoseconds"]),
        message_count=int(info["message_count"]),
        topics=topics,
        compression_format=str(info["compression_format"] or ""),
        compression_mode=str(info["compression_mode"] or ""),
        custom_data={str(k): str(v) for k, v in (info["custom_data"] or {}).items()},
        ros_distro=str(info["ros_distro"]),
    )
