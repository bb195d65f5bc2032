"""Which graph topics a recorder records: include/exclude regular expressions and hidden topics."""

from __future__ import annotations

import re
from dataclasses import dataclass


def is_hidden(topic: str) -> bool:
    """Whether a topic is hidden in ROS 2 terms: one of its name tokens starts with an underscore."""
    return any(token.startswith("_") for token in topic.split("/") if token)


@dataclass(frozen=True)
class TopicSelection:
    """Which topics to record, like `ros2 bag record -a --regex ... --exclude-regex ...`.

    A topic is selected when it matches `include`, does not match `exclude`, and is not hidden (unless
    `include_hidden`).

    Attributes:
        include: regular expression searched in the fully qualified topic name ("" selects nothing).
        exclude: regular expression; matching topics are never selected ("" excludes nothing).
        include_hidden: also select hidden topics (action feedback and status, ...).
    """

    include: str = ".*"
    exclude: str = ""
    include_hidden: bool = False

    def __post_init__(self) -> None:
        for field in ("include", "exclude"):
            try:
                re.compile(getattr(self, field))
            except re.error as err:
                raise ValueError(
                    f"{field} is not a regular expression: {getattr(self, field)!r} ({err})"
                ) from err

    def matches(self, topic: str) -> bool:
        """Whether `topic` (fully qualified) is selected."""
        if not self.include or re.search(self.include, topic) is None:
            return False
        if self.exclude and re.search(self.exclude, topic) is not None:
            return False
        return self.include_hidden or not is_hidden(topic)
