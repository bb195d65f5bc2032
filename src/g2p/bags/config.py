"""The recorder's configuration (one ROS parameter per field in the recorder node)."""

from __future__ import annotations

from dataclasses import dataclass

from g2p.bags.runs import is_safe_name
from g2p.bags.selection import TopicSelection
from g2p.validation import ConfigError, require, require_positive


@dataclass(frozen=True)
class RecorderConfig:
    """How runs are recorded.

    Attributes:
        bags_dir: directory holding one bag directory per run (relative to the working directory).
        run_id: id of this run (its directory name); empty for a new one from the UTC time and a
            random suffix.
        include_regex: record topics whose fully qualified name matches this regular expression.
        exclude_regex: never record topics matching this regular expression (empty: none excluded).
        include_hidden: also record hidden topics (names with a token starting with an underscore).
        discovery_period_s: period of polling the graph for new topics (s).
        queue_depth: depth of each recording subscription's queue (messages): the backlog a topic may
            build up while the recorder falls behind (20 s at 5,000 ticks/s). Memory is used only by a
            backlog (a few hundred bytes per message).
        chunk_period_s: the pending chunk is compressed and written at least this often (s), so a
            killed recorder loses at most this much of the recording (and at most one chunk).
        drain_timeout_s: on SIGINT/SIGTERM, keep recording until the other publishers of the recorded
            topics have left and what they sent is written, for up to this long, before closing the bag
            (s; within the 5 s that `ros2 launch` grants a process before it escalates to SIGTERM).
    """

    bags_dir: str = "bags"
    run_id: str = ""
    include_regex: str = ".*"
    exclude_regex: str = ""
    include_hidden: bool = False
    discovery_period_s: float = 0.1
    queue_depth: int = 100000
    chunk_period_s: float = 1.0
    drain_timeout_s: float = 4.0

    def __post_init__(self) -> None:
        require(bool(self.bags_dir), "bags_dir", "must not be empty")
        require(
            not self.run_id or is_safe_name(self.run_id),
            "run_id",
            f"must be a plain directory name (letters, digits, '_', '-', '.') or empty, got {self.run_id!r}",
        )
        try:
            self.selection()
        except ValueError as err:
            raise ConfigError(str(err)) from err
        require_positive(self.discovery_period_s, "discovery_period_s")
        require(self.queue_depth >= 1, "queue_depth", f"must be >= 1, got {self.queue_depth}")
        require_positive(self.chunk_period_s, "chunk_period_s")
        require_positive(self.drain_timeout_s, "drain_timeout_s")

    def selection(self) -> TopicSelection:
        """The topic selection these settings describe."""
        return TopicSelection(self.include_regex, self.exclude_regex, self.include_hidden)
