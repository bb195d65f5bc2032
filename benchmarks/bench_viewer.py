"""Measure what the live viewer costs: per tick in its process, and on the main job through the graph.

1. Per tick (in-process, no ROS): `LegViewer.joint_state` on the sample bag's joint states, with a real
   Foxglove client (tests/foxglove_client, @foxglove/ws-protocol) subscribed to every channel, the 3D
   scene at its default 30 Hz of wall time; and building plus logging one scene update alone.
2. The main job (`bringup`, fast simulation, no report) with and without `--view`, interleaved, with a
   client connected throughout when the viewer runs: wall time and the learner's result.

Run:  scripts/with-env python benchmarks/bench_viewer.py [--runs 2] [--skip-graph]
"""

from __future__ import annotations

import argparse
import re
import shutil
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from g2p.bags.reader import BagReader
from g2p.bags.ticks import header_stamp_ns
from g2p.description.urdf import packaged_leg_description
from g2p.viewer.server import LegViewer, ViewerConfig

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "bags" / "samples" / "treadmill-60s-babbling"
CLIENT = ROOT / "tests" / "foxglove_client" / "client.mjs"


def client(url: str, seconds: float) -> subprocess.Popen[bytes]:
    """The tests' Foxglove client, subscribed to every channel until the server closes."""
    node = shutil.which("node")
    assert node is not None, "the benchmark's client needs Node.js (scripts/bootstrap installs its packages)"
    return subprocess.Popen(
        [node, str(CLIENT), url, "--seconds", str(seconds), "--until-close"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


def per_tick() -> None:
    """Print the viewer's cost per tick and per scene update, a client subscribed."""
    with BagReader(SAMPLE) as reader:
        states = [
            (header_stamp_ns(m.msg.header), np.asarray(m.msg.position[:2]), np.asarray(m.msg.velocity[:2]))
            for m in reader.messages(["/leg/joint_states"])
        ]
    with LegViewer(packaged_leg_description(), ViewerConfig(port=0)) as viewer:
        proc = client(viewer.url, 120)
        assert viewer.wait_for_client(channels=3, timeout_s=60)
        costs = []
        for stamp, q, v in states:
            t0 = time.perf_counter_ns()
            viewer.joint_state(stamp, q, v)
            costs.append(time.perf_counter_ns() - t0)
            time.sleep(0.0005)  # ~1,000 ticks a second of wall time, as in fast simulation
        frame = viewer.state.scene()
        assert frame is not None
        scene = []
        for _ in range(500):
            t0 = time.perf_counter_ns()
            viewer.channels.log_scene(frame, viewer.state.description)
            scene.append(time.perf_counter_ns() - t0)
    proc.wait(30)
    us = np.array(costs) / 1e3
    print(
        f"joint_state, {len(us)} ticks with a client: median {np.median(us):.0f} us, "
        f"p99 {np.percentile(us, 99):.0f} us, max {us.max():.0f} us"
    )
    print(f"one scene update built and logged: median {np.median(np.array(scene) / 1e3):.0f} us")


def main_job(view: bool, port: int) -> tuple[float, str]:
    """The main job through `bringup` (with viewer and client when `view`): wall time (s), best reward."""
    with tempfile.TemporaryDirectory() as tmp:
        bringup = [str(ROOT / "scripts" / "ros2-run"), "g2p_bringup", "bringup"]
        args = [*bringup, "--no-report", "--bags-dir", tmp]
        proc = None
        if view:
            args += ["--view", "--set", f"viewer.port={port}"]
            proc = client(f"ws://127.0.0.1:{port}", 300)
        t0 = time.monotonic()
        out = subprocess.run(args, capture_output=True, text=True, check=True, cwd=tmp).stdout
        wall = time.monotonic() - t0
        if proc is not None:
            proc.wait(30)
    best = re.findall(r"\| (\d+\.\d) \|\n", out)
    return wall, best[-1] if best else "?"


def main() -> None:
    """Run the benchmark."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=2, help="main-job runs each way")
    parser.add_argument("--skip-graph", action="store_true", help="only the per-tick figures")
    options = parser.parse_args()
    per_tick()
    if options.skip_graph:
        return
    walls: dict[bool, list[float]] = {False: [], True: []}
    for k in range(options.runs):
        for view in (False, True):
            wall, best = main_job(view, 8765 + k)
            walls[view].append(wall)
            print(f"main job {'with' if view else 'without'} --view: {wall:.1f} s, best reward {best} mm")
    for view, w in walls.items():
        print(f"{'with' if view else 'without'} --view: median {statistics.median(w):.1f} s ({w})")


if __name__ == "__main__":
    main()
