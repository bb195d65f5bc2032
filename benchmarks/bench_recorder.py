"""Recorder throughput against the fast simulation's rate, and bag size per minute of rig time.

Three measurements on this machine:
    end to end: the installed `record` executable recording the fake rig of tests/ros/fake_rig_publisher.py
        (a separate process publishing joint_states, treadmill, motor_power, applied_activation and /clock
        every tick, plus /diagnostics, learner events and maps) as fast as it can publish. Reports the
        publisher's tick rate, messages and MB (serialized payload) recorded per second of the publishing
        window, the recorder's CPU time per message, and messages lost per reliable topic. Run once with the
        contract's publisher history (SAMPLE_QOS depth 200) and once with a deep one (10000).
    writer alone: g2p.bags.BagWriter.write of rig-sized messages in this process (messages/s, MB/s), the
        ceiling of the recorder's bag I/O.
    bag size: bytes of bag (MCAP + metadata.yaml) per minute of rig time at 78 Hz, with signals that change
        every tick like real ones (random walks), for zstd-compressed chunks and without compression.

Run:  scripts/with-env python benchmarks/bench_recorder.py [--ticks 30000] [--runs 2]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from ament_index_python.packages import get_package_prefix
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import StoragePlugin, Writer
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from g2p.bags import BagReader, BagWriter, InterfaceLibrary, TopicSpec, TypeRegistry, ament_share_dirs
from g2p.plant import NOMINAL_TICK_HZ
from g2p_interfaces.msg import MotorActivation, MotorPower, Treadmill

ROOT = Path(__file__).resolve().parents[1]
RECORD = Path(get_package_prefix("g2p_recorder")) / "lib" / "g2p_recorder" / "record"
FAKE_RIG = ROOT / "tests" / "nodes" / "fake_rig_publisher.py"
RELIABLE = [
    "/leg/joint_states",
    "/leg/treadmill",
    "/leg/motor_power",
    "/leg/applied_activation",
    "/diagnostics",
    "/leg/learner/events",
    "/leg/learner/inverse_map",
]


def cpu_s(pid: int) -> float:
    """User + system CPU time of a process (s)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def end_to_end(ticks: int, depth: int, workdir: Path) -> dict[str, float]:
    """Record the fake rig publishing `ticks` ticks unpaced; return rates, CPU per message and losses."""
    bags = workdir / f"bags-{depth}-{time.monotonic_ns()}"
    env = os.environ.copy()
    recorder = subprocess.Popen(
        [str(RECORD), "--ros-args", "-p", f"bags_dir:={bags}"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=env,
    )
    try:
        deadline = time.monotonic() + 30
        while not (bags.is_dir() and any(bags.iterdir())) and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(1.0)  # let the recorder's start-up work finish before reading its CPU time
        cpu_before = cpu_s(recorder.pid)
        rig = subprocess.run(
            [sys.executable, str(FAKE_RIG), "publish", "--ticks", str(ticks), "--depth", str(depth)],
            capture_output=True,
            text=True,
            env=env,
            timeout=600,
        )
        if rig.returncode != 0:
            raise RuntimeError(f"the fake rig failed:\n{rig.stdout}\n{rig.stderr}")
        last = cpu_s(recorder.pid)
        while True:  # wait until the recorder has written everything it received
            time.sleep(0.5)
            now = cpu_s(recorder.pid)
            if now - last < 0.02:
                break
            last = now
        cpu_used = last - cpu_before
        recorder.send_signal(signal.SIGINT)
        recorder.wait(timeout=120)
    finally:
        if recorder.poll() is None:
            recorder.kill()
            recorder.wait()
    result = json.loads(rig.stdout.strip().splitlines()[-1])
    (bag,) = bags.iterdir()
    with BagReader(bag) as reader:
        counts = {n: t.message_count for n, t in reader.topics.items()}
        stamps, size = [], 0
        for m in reader.raw_messages([t for t in [*RELIABLE, "/clock"] if t in reader.topics]):
            stamps.append(m.timestamp_ns)
            size += len(m.data)
    window_s = (max(stamps) - min(stamps)) * 1e-9
    recorded = len(stamps)
    lost = {t: result["published"][t] - counts.get(t, 0) for t in RELIABLE}
    shutil.rmtree(bags)
    return {
        "publisher_ticks_per_s": result["ticks_per_s"],
        "messages_per_s": recorded / window_s,
        "mb_per_s": size / window_s / 1e6,
        "cpu_us_per_message": 1e6 * cpu_used / recorded,
        "lost_reliable": float(sum(lost.values())),
        "published": float(sum(result["published"].values())),
        "clock_lost": float(result["published"]["/clock"] - counts.get("/clock", 0)),
    }


def rig_minute(
    seconds: float = 60.0, rate_hz: float = NOMINAL_TICK_HZ, seed: int = 0
) -> list[tuple[str, int, bytes]]:
    """(topic, timestamp ns, CDR) of `seconds` of rig time with every value changing every tick."""
    rng = np.random.default_rng(seed)
    n = int(seconds * rate_hz)
    q = np.cumsum(rng.normal(0, 0.01, (n, 2)), axis=0)
    a = np.clip(0.15 + np.abs(np.cumsum(rng.normal(0, 0.02, (n, 3)), axis=0)), 0.15, 1.0)
    out = []
    for k in range(n):
        ns = int(1.7e18) + int(k * 1e9 / rate_hz)
        stamp = Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
        h = Header(stamp=stamp, frame_id="leg")
        out += [
            ("/clock", ns, serialize_message(Clock(clock=stamp))),
            (
                "/leg/joint_states",
                ns,
                serialize_message(
                    JointState(
                        header=h,
                        name=["proximal", "distal"],
                        position=q[k].tolist(),
                        velocity=rng.normal(size=2).tolist(),
                    )
                ),
            ),
            (
                "/leg/treadmill",
                ns,
                serialize_message(
                    Treadmill(
                        header=h,
                        displacement_mm=float(k * 0.3 + rng.normal()),
                        velocity_mm_s=float(rng.normal(20, 5)),
                    )
                ),
            ),
            (
                "/leg/motor_power",
                ns,
                serialize_message(
                    MotorPower(
                        header=h,
                        current_a=rng.uniform(0, 2, 3).tolist(),
                        power_w=rng.uniform(0, 20, 3).tolist(),
                        energy_j=(k * rng.uniform(0.9, 1.1, 3)).tolist(),
                    )
                ),
            ),
            (
                "/leg/applied_activation",
                ns,
                serialize_message(MotorActivation(header=h, activation=a[k].tolist())),
            ),
        ]
        if k % 78 == 0:
            out.append(
                (
                    "/diagnostics",
                    ns,
                    serialize_message(
                        DiagnosticArray(
                            header=h,
                            status=[
                                DiagnosticStatus(
                                    name="/leg/sim: rig",
                                    message="ok",
                                    hardware_id="MujocoLeg",
                                    values=[
                                        KeyValue(key=key, value=str(k))
                                        for key in ("ticks", "commands_accepted", "plant_faults")
                                    ],
                                )
                            ],
                        )
                    ),
                )
            )
    return out


TYPES = {
    "/clock": "rosgraph_msgs/msg/Clock",
    "/leg/joint_states": "sensor_msgs/msg/JointState",
    "/leg/treadmill": "g2p_interfaces/msg/Treadmill",
    "/leg/motor_power": "g2p_interfaces/msg/MotorPower",
    "/leg/applied_activation": "g2p_interfaces/msg/MotorActivation",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
}


def write_bag(path: Path, msgs: list[tuple[str, int, bytes]], registry: TypeRegistry) -> float:
    """Write `msgs` into a new bag; return the seconds spent in BagWriter calls."""
    start = time.perf_counter()
    with BagWriter(path) as writer:
        handles = {t: writer.add_topic(TopicSpec(t, registry.definition(m))) for t, m in TYPES.items()}
        for topic, ns, data in msgs:
            writer.write(handles[topic], ns, data)
    return time.perf_counter() - start


def bag_bytes(path: Path) -> int:
    """Bytes of all files of a bag directory."""
    return sum(f.stat().st_size for f in path.iterdir())


def main() -> None:
    """Run the three measurements and print them."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ticks", type=int, default=30000, help="ticks per end-to-end run")
    parser.add_argument("--runs", type=int, default=2, help="end-to-end runs per publisher depth")
    ns = parser.parse_args()
    registry = TypeRegistry(InterfaceLibrary(ament_share_dirs()))
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f} at start")
        print(
            f"\nend to end: `record` against the fake rig, {ns.ticks} ticks unpaced, {ns.runs} runs per depth"
        )
        for depth in (200, 10000):
            rows = [end_to_end(ns.ticks, depth, work) for _ in range(ns.runs)]
            med = {k: statistics.median(r[k] for r in rows) for k in rows[0]}
            print(
                f"  publisher depth {depth:>5}: publisher {med['publisher_ticks_per_s']:,.0f} ticks/s -> "
                f"recorder {med['messages_per_s']:,.0f} msg/s, {med['mb_per_s']:.2f} MB/s, "
                f"{med['cpu_us_per_message']:.1f} us CPU/msg; lost reliable "
                f"{[int(r['lost_reliable']) for r in rows]} of {int(med['published'])}, "
                f"/clock (best effort) lost {[int(r['clock_lost']) for r in rows]}"
            )
        minute = rig_minute()
        payload = sum(len(d) for _, _, d in minute)
        elapsed = write_bag(work / "minute", minute, registry)
        print(
            f"\nwriter alone: {len(minute) / elapsed:,.0f} msg/s, {payload / elapsed / 1e6:.1f} MB/s "
            f"(BagWriter.write, zstd chunks, {len(minute)} messages)"
        )
        many = minute * 10
        elapsed = write_bag(work / "many", many, registry)
        print(f"              {len(many) / elapsed:,.0f} msg/s over {len(many)} messages")
        print(
            f"\nbag size at 78 Hz (4 rig topics + /clock per tick, /diagnostics at 1 Hz): "
            f"{len(minute)} messages, {payload / 1e6:.2f} MB of CDR per minute"
        )
        print(
            f"  zstd chunks: {bag_bytes(work / 'minute') / 1e6:.2f} MB per minute of rig time "
            f"({bag_bytes(work / 'minute') * 60 / 1e6:.0f} MB per hour)"
        )
        plain = work / "plain"
        with Writer(plain, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            conns = {
                t: writer.add_connection(
                    t, m, msgdef=registry.definition(m).msgdef, rihs01=registry.definition(m).rihs01
                )
                for t, m in TYPES.items()
            }
            for topic, t_ns, data in minute:
                writer.write(conns[topic], t_ns, data)
        print(f"  uncompressed MCAP: {bag_bytes(plain) / 1e6:.2f} MB per minute")


if __name__ == "__main__":
    main()
