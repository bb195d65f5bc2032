"""How fast Ctrl-C stops the main job while the inverse map is being fitted.

    scripts/with-env python benchmarks/bench_stop.py [--repeats 3]

Starts `bringup` (the main job: 300 s of babbling in fast simulation), sends SIGINT as soon as the learner
reports babbling done (the fit on the babbling data starts then), and measures the time until `bringup`
has exited: the learner cancels its goal (the fit stops at its next iteration), then the rig and the
recorder stop and the bag is closed.
"""

from __future__ import annotations

import argparse
import json
import signal
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

from ament_index_python.packages import get_package_prefix


def stop_after_babbling(workdir: Path) -> float:
    """One run: seconds from SIGINT (right after babbling) to bringup's exit."""
    exe = Path(get_package_prefix("g2p_bringup")) / "lib" / "g2p_bringup" / "bringup"
    proc = subprocess.Popen(
        [str(exe), "--no-report"], cwd=workdir, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    assert proc.stdout is not None
    for line in proc.stdout:
        if "babbling 100%" in line:
            break
    else:
        raise RuntimeError(f"bringup ended before babbling was done (exit {proc.wait()})")
    start = time.monotonic()
    proc.send_signal(signal.SIGINT)
    proc.communicate(timeout=120)
    return time.monotonic() - start


def main() -> None:
    """Measure and print the stop times (s)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="g2p-stop-") as tmp:
        times = [round(stop_after_babbling(Path(tmp)), 2) for _ in range(args.repeats)]
    print(json.dumps({"stop_s": times, "median_s": statistics.median(times)}))


if __name__ == "__main__":
    main()
