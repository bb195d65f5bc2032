"""Whether Fast DDS shared-memory files left in /dev/shm by killed processes slow a later graph.

    scripts/with-env python benchmarks/bench_stale_shm.py [--killed 5] [--steps 500] [--repeats 2]

Measures the TickPlant round trip in fast time (benchmarks/bench_tick_plant.py: a `sim` process and a
policy's node stepping it in lockstep) three ways, `--repeats` times each, in this ROS domain:
1. clean: after `fastdds shm clean` (removes the files whose owners are dead);
2. stale: after `--killed` such pairs were SIGKILLed mid-run, leaving their ports and segments;
3. cleaned: after `fastdds shm clean` again.
Prints one JSON line per measurement and the count of Fast DDS files in /dev/shm before each.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

HERE = Path(__file__).resolve().parent
SHM = Path("/dev/shm")


def shm_files() -> int:
    """Fast DDS's files in /dev/shm (2.x names them fastrtps_*, 3.x fastdds_*)."""
    return sum(1 for p in SHM.iterdir() if p.name.startswith(("fastdds_", "fastrtps_")))


def clean() -> str:
    """`fastdds shm clean`: what it reports."""
    done = subprocess.run(["fastdds", "shm", "clean"], capture_output=True, text=True, check=True)
    return " ".join(done.stdout.split())


def measure(steps: int) -> dict[str, object]:
    """One bench_tick_plant run in fast time."""
    done = subprocess.run(
        [sys.executable, str(HERE / "bench_tick_plant.py"), "--steps", str(steps), "--realtime-steps", "0"],
        capture_output=True,
        text=True,
        check=True,
        timeout=600,
    )
    return json.loads(done.stdout.splitlines()[-1])


def leave_stale(killed: int) -> None:
    """Start `killed` sim-and-policy pairs one after another and SIGKILL each mid-run."""
    for _ in range(killed):
        bench = subprocess.Popen(
            [sys.executable, str(HERE / "bench_tick_plant.py"), "--steps", "100000", "--realtime-steps", "0"],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
        time.sleep(6.0)  # discovered and stepping
        os.killpg(bench.pid, signal.SIGKILL)
        bench.wait()


def main() -> None:
    """Entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--killed", type=int, default=5, help="killed pairs that leave their files")
    parser.add_argument("--steps", type=int, default=500, help="TickPlant steps per measurement")
    parser.add_argument("--repeats", type=int, default=2, help="measurements per condition")
    args = parser.parse_args()
    for condition in ("clean", "stale", "cleaned"):
        if condition == "stale":
            leave_stale(args.killed)
            note = f"{args.killed} pairs killed"
        else:
            note = clean()
        for _ in range(args.repeats):
            files = shm_files()
            result = measure(args.steps)
            print(
                json.dumps({"condition": condition, "shm_files": files, "note": note, **result}), flush=True
            )


if __name__ == "__main__":
    main()
