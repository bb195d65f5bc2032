"""Bag I/O for the G2P rig: record, read, recover, replay planning, training data and run reports.

ROS-free: the ROS nodes in g2p_ros wire subscriptions and publishers and call this package. Bags are
rosbag2 format version 9 with MCAP storage and zstd-compressed chunks (see docs/BAGS.md).

May import: g2p.description, g2p.inverse_map, g2p.rig, g2p.learning.
"""

from typing import TYPE_CHECKING, Any

from g2p.bags.dataset import RecordedAttempt, RunData, TrainingData, load_run, load_training_data
from g2p.bags.errors import BagError, BagReadError, BagWriteError, InterfaceError, RecoveryError
from g2p.bags.interfaces import InterfaceLibrary, TypeDefinition, TypeRegistry, ament_share_dirs
from g2p.bags.metadata import BagMetadata, TopicInfo, read_metadata
from g2p.bags.reader import BagReader, DecodedMessage, RawMessage
from g2p.bags.recover import RecoveryResult, bag_is_complete, recover_bag, recoverable_counts
from g2p.bags.writer import BagWriter, TopicSpec, create_run_bag

if TYPE_CHECKING:
    from g2p.bags.report import ReportResult, write_report


def __getattr__(name: str) -> Any:
    # The report draws with matplotlib (a third of a second to import): loaded when first asked for, so
    # the recorder and the learner start without it.
    if name in ("ReportResult", "write_report"):
        from g2p.bags import report

        return getattr(report, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "BagError",
    "BagMetadata",
    "BagReadError",
    "BagReader",
    "BagWriteError",
    "BagWriter",
    "DecodedMessage",
    "InterfaceError",
    "InterfaceLibrary",
    "RawMessage",
    "RecordedAttempt",
    "RecoveryError",
    "RecoveryResult",
    "ReportResult",
    "RunData",
    "TopicInfo",
    "TopicSpec",
    "TrainingData",
    "TypeDefinition",
    "TypeRegistry",
    "ament_share_dirs",
    "bag_is_complete",
    "create_run_bag",
    "load_run",
    "load_training_data",
    "read_metadata",
    "recover_bag",
    "recoverable_counts",
    "write_report",
]
