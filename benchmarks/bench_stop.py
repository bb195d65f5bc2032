"""How fast Ctrl-C stops the main job while the inverse map is being fitted.

    scripts/with-env python benchmarks/bench_stop.py [--repeats 3]

Starts `bringup` (the main job: 300 s of babbling in fast simulation), sends SIGINT as soon as the learner
reports babbling done (the fit on the babbling data starts then), and measures the time until `bringup`
has exited: the learner cancels its goal (the fit stops at its next iteration), then the rig and the
recorder stop and the bag is closed. Reports both: the learner's exit and bringup's.
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


def _learner_pid() -> int | None:
    """The pid of the running `learn` process (bringup's main node), if any."""
    for proc in Path("/proc").iterdir():
        if proc.name.isdigit():
            try:
                if b"g2p_learner/learn" in (proc / "cmdline").read_bytes():
                    return int(proc.name)
            except OSError:
                continue
    return None


def stop_after_babbling(workdir: Path) -> tuple[float, float]:
    """One run: seconds from SIGINT (right after babbling) to the learner's exit and to bringup's."""
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
    learner = _learner_pid()
    start = time.monotonic()
    proc.send_signal(signal.SIGINT)
    while learner is not None and Path(f"/proc/{learner}").exists():
        time.sleep(0.01)
    learner_s = time.monotonic() - start
    proc.communicate(timeout=120)
    return learner_s, time.monotonic() - start


def main() -> None:
    """Measure and print the stop times (s)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="g2p-stop-") as tmp:
        runs = [stop_after_babbling(Path(tmp)) for _ in range(args.repeats)]
    learner, bringup = ([round(r[k], 2) for r in runs] for k in (0, 1))
    print(
        json.dumps(
            {
                "learner_exit_s": learner,
                "bringup_exit_s": bringup,
                "median_learner_s": statistics.median(learner),
                "median_bringup_s": statistics.median(bringup),
            }
        )
    )


if __name__ == "__main__":
    main()
