"""`ros2 run g2p_ros recover_bag bags/<run>`: make the bag of a killed recorder readable again.

Rebuilds `<run>.mcap` (indexed, with summary) and metadata.yaml from every complete chunk of what the
recorder wrote, losing at most the chunk it was filling; the old file is kept as `<run>.mcap.damaged`.
A complete bag is left alone unless --force. Errors give one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from g2p.bags import BagError, recover_bag


def main(args: list[str] | None = None) -> None:
    """Recover one bag; exit 2 with one line on stderr when it cannot be recovered."""
    parser = argparse.ArgumentParser(
        prog="recover_bag", description="Rebuild a readable bag from what a killed recorder wrote."
    )
    parser.add_argument("bag", type=Path, help="the bag directory (bags/<run-id>)")
    parser.add_argument("--force", action="store_true", help="rebuild even when the bag is complete")
    ns = parser.parse_args(sys.argv[1:] if args is None else args)
    try:
        result = recover_bag(ns.bag, force=ns.force)
    except BagError as err:
        print(f"recover_bag: error: {err}", file=sys.stderr)
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
