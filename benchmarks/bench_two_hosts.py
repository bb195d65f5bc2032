"""The graph on two hosts over a bad network: what each fault costs, a soak, and the main job's wall time.

    scripts/with-env python benchmarks/bench_two_hosts.py [faults] [placement] [rediscovery] [walltime] [soak]
        [--soak-rig-min 60]

Runs on two hosts (g2p_twohost: two network namespaces joined by a
user-space link with delay, loss and partitions; needs root). The rig side runs ROS 2 Jazzy with the
recorder beside it, the learner runs on this session's distribution, every process the installed
executable.

- faults: one learning run per fault, the rig paced in real time as the hardware is (`sim`, realtime):
  a 3 s partition during an attempt, a partition of 10 s against a 4 s limit, the rig killed and
  restarted, the learner killed and resumed (`learn --resume`), the recorder killed; and the run over a
  link with 20 ms +- 10 ms one-way delay and 2 % loss. For each: time to detect the fault (the learner's
  rig_lost event), time until the rig applies baseline, attempts retried, rig samples lost (published by
  the rig, not in the bag) and the run's extra wall time against the same run on a clean link.
- placement: rig samples lost by the recorder beside the rig and by one on the workstation, over a 30 s
  partition (longer than the 20 s DDS keeps a silent peer).
- rediscovery: after a 30 s partition, time from the link's return to the first message across it, with
  multicast discovery (ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET) and with ROS_STATIC_PEERS.
- soak: `--soak-rig-min` minutes of rig time (fast simulation) over the impaired link with a random 1-5 s
  partition every 20-40 s of wall time; attempts completed and retried, samples lost, each process's
  resident memory after babbling and at the end, processes restarted by hand (none).
- walltime: the main job (`make run`'s settings) on two hosts over a clean link and over the impaired
  one, against the same run on one host.
"""

from __future__ import annotations

import argparse
import json
import random
import signal
import subprocess
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
from ament_index_python.packages import get_package_prefix

from g2p.bags.dataset import RunData, load_run
from g2p.bags.recover import recover_bag
from g2p.plant import NOMINAL_TICK_HZ
from g2p.safety import BASELINE_ACTIVATION
from g2p_twohost.graph import HostProcess, TwoHostGraph, ros_params
from g2p_twohost.hosts import TwoHosts

ROOT = Path(__file__).resolve().parents[1]

NS = ["--ros-args", "-r", "__ns:=/leg"]
# Realtime runs: 8 s of babbling, attempts of 4 cycles (about 4 s), 1 exploration + 3 exploitation.
REALTIME = {
    "learner.seed": "0",
    "learner.babbling.duration_s": "8.0",
    "cycle.n_cycles": "4",
    "search.threshold_mm": "-1000.0",
    "search.exploitation_attempts": "3",
}
IMPAIRED = {"delay_ms": 20.0, "jitter_ms": 10.0, "loss": 0.02}
PROBE = ROOT / "benchmarks" / "two_host_probe.py"


def rss_mb(pid: int) -> float:
    """Resident memory of a process (MB)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def missing_ticks(run: RunData) -> int:
    """Ticks missing between the bag's first and last tick.

    Stamps advance one tick period per tick (simulated time, in fast and in realtime mode), so a gap of
    n periods is n - 1 ticks not recorded.
    """
    stamps = np.unique(run.ticks.stamps_ns) * 1e-9
    gaps = np.round(np.diff(stamps) * NOMINAL_TICK_HZ) - 1
    return int(gaps[gaps > 0].sum())


def published(log: str) -> int:
    """The rig's own count of the ticks it published (its last log line)."""
    lines = [ln for ln in log.splitlines() if "stopped after publishing" in ln]
    return int(lines[-1].split("stopped after publishing ")[1].split()[0]) if lines else -1


class Run:
    """One learning run on two hosts: rig (sim) and recorder on the rig host, the learner on the other."""

    def __init__(self, hosts: TwoHosts, workdir: Path, run_id: str, params: dict[str, str], mode: str):
        self.g = TwoHostGraph(hosts, ROOT, workdir, run_id)
        self.sim_args = [*NS, "-p", f"time_mode:={mode}"]
        self.learn_args = [*NS, "-p", "recorder_node:=recorder", *ros_params(params)]
        if mode == "fast":
            self.learn_args += ["-p", "use_sim_time:=true"]
        self.sims: list[HostProcess] = []
        self.resumed: HostProcess | None = None  # a learner started with --resume
        self.sim = self.start_sim()
        self.recorder = self.g.node("rig", "g2p_recorder", "record", *NS, "-p", f"run_id:={run_id}")
        self.started = time.monotonic()
        self.learner = self.g.node("ws", "g2p_learner", "learn", *self.learn_args)

    def start_sim(self) -> HostProcess:
        """Start (or start again) the simulated rig on the rig host."""
        self.sim = self.g.node("rig", "g2p_sim", "sim", *self.sim_args)
        self.sims.append(self.sim)
        return self.sim

    def finish(self, learner: HostProcess | None = None, timeout_s: float = 1800.0) -> dict[str, Any]:
        """Wait for the learner, stop the rig side; the run's wall time, bag and sample counts."""
        learner = learner or self.learner
        code = learner.wait(timeout_s)
        wall = time.monotonic() - self.started
        for sim in self.sims:
            sim.stop()
        if self.recorder.popen.poll() is None:
            self.recorder.stop()
        else:
            recover_bag(self.g.bag)
        run = load_run(self.g.bag)
        sent = sum(published(s.log()) for s in self.sims)
        return {
            "exit": code,
            "wall_s": wall,
            "run": run,
            "published": sent,
            "recorded": len(run.ticks.recording),
        }


def events(run: RunData, name: str) -> list[Any]:
    """The run's learner events of one kind, in stamp order."""
    return [e for e in run.events if e.event == name]


def baseline_after(run: RunData, t_s: float) -> float:
    """Seconds from `t_s` until the rig applied baseline on every motor (from the bag's ticks)."""
    rec = run.ticks.recording
    after = np.flatnonzero((rec.t_s >= t_s) & np.all(rec.activation == BASELINE_ACTIVATION, axis=1))
    return float(rec.t_s[after[0]] - t_s) if len(after) else float("nan")


def fault_row(
    name: str, result: dict[str, Any], clean_wall_s: float, fault_t: float | None
) -> dict[str, Any]:
    """A table row: what a fault cost the run."""
    run: RunData = result["run"]
    lost = events(run, "rig_lost")
    detect = lost[0].stamp_ns * 1e-9 - fault_t if lost and fault_t is not None else float("nan")
    return {
        "fault": name,
        "completed": result["exit"] == 0,
        "attempts": len({e.attempt for e in events(run, "attempt_end")}),
        "detect_s": round(detect, 2),
        "baseline_s": round(baseline_after(run, fault_t), 3) if fault_t is not None else float("nan"),
        "retried": sum(1 for e in lost if e.detail.get("call") == "play"),
        "samples_lost": missing_ticks(run),
        # The first few ticks reach the recorder on some of the four topics only, while it subscribes.
        "incomplete_at_start": run.ticks.incomplete,
        "extra_wall_s": round(result["wall_s"] - clean_wall_s, 1),
    }


def _partition(seconds: float) -> Any:
    """A fault: cut the link `seconds` (s), one second into the second attempt."""

    def act(hosts: TwoHosts, run: Run) -> float:
        run.learner.wait_for_attempt(1)
        time.sleep(1.0)
        t = time.time()
        hosts.partition()
        time.sleep(seconds)
        hosts.restore()
        return t

    return act


def _restart_rig(hosts: TwoHosts, run: Run) -> float:
    run.learner.wait_for_attempt(1)
    time.sleep(1.0)
    t = time.time()
    run.sim.stop(signal.SIGKILL)
    time.sleep(1.0)
    run.start_sim()
    return t


def _kill_learner(hosts: TwoHosts, run: Run) -> float:
    run.learner.wait_for_attempt(2)
    time.sleep(1.0)
    t = time.time()
    run.learner.stop(signal.SIGKILL)
    run.resumed = run.g.node("ws", "g2p_learner", "learn", "--resume", str(run.g.bag), *run.learn_args)
    return t


def _kill_recorder(hosts: TwoHosts, run: Run) -> float:
    run.learner.wait_for_attempt(2)
    run.recorder.stop(signal.SIGKILL)
    return time.time()


def _impair(hosts: TwoHosts, run: Run) -> None:
    hosts.impair(**IMPAIRED)


FAULTS: list[tuple[str, Any, dict[str, str]]] = [
    ("partition 3 s during an attempt", _partition(3.0), REALTIME),
    ("partition 10 s, limit 4 s", _partition(10.0), {**REALTIME, "rig_lost_limit_s": "4.0"}),
    ("rig killed, restarted 1 s later", _restart_rig, REALTIME),
    ("learner killed, resumed", _kill_learner, REALTIME),
    ("recorder killed", _kill_recorder, REALTIME),
    ("20 +- 10 ms, 2 % loss", _impair, REALTIME),
]


def faults(workdir: Path) -> list[dict[str, Any]]:
    """One realtime run per fault, and a clean one for the extra wall time."""

    def bench_run(k: int, action: Any, params: dict[str, str]) -> tuple[Run, dict[str, Any], float | None]:
        with TwoHosts() as hosts:
            run = Run(hosts, workdir / f"fault{k}", f"fault{k}", params, "realtime")
            t = action(hosts, run) if action is not None else None
            return run, run.finish(run.resumed), t

    _, clean, _ = bench_run(0, None, REALTIME)
    rows = [fault_row("none (clean link)", clean, clean["wall_s"], None)]
    for k, (name, action, params) in enumerate(FAULTS, start=1):
        run, result, t = bench_run(k, action, params)
        row = fault_row(name, result, clean["wall_s"], t if action is not _kill_learner else None)
        if action is _kill_learner and t is not None:
            restart = next(e for e in events(result["run"], "run_start") if "resumed_from" in e.detail)
            row["resumed_after_attempt"] = restart.detail["resumed_from"]["attempt"]
        row["says_how_to_resume"] = "learn --resume" in run.learner.log()
        rows.append(row)
    return rows


def soak(workdir: Path, rig_minutes: float, seed: int = 0) -> dict[str, Any]:
    """A long run (fast simulation) over the impaired link with random partitions."""
    attempts = int(np.ceil((rig_minutes * 60 - 60) / 20.5))
    params = {
        "learner.seed": "0",
        "learner.babbling.duration_s": "60.0",
        "learner.inverse_map.max_iterations_refine": "2",  # the soak is about the link, not the map
        "search.threshold_mm": "1000000.0",  # never crosses: exploration to the budget
        "search.max_exploration_attempts": str(attempts),
        "rig_lost_limit_s": "60.0",
    }
    rng = random.Random(seed)
    partitions: list[float] = []
    with TwoHosts() as hosts:
        hosts.impair(**IMPAIRED)
        run = Run(hosts, workdir / "soak", "soak", params, "fast")
        run.learner.wait_for_attempt(1)
        procs = {"sim": run.sim, "recorder": run.recorder, "learner": run.learner}
        rss_start = {k: rss_mb(p.popen.pid) for k, p in procs.items()}
        rss_end: dict[str, float] = {}
        stop = threading.Event()

        def cut() -> None:
            while not stop.wait(rng.uniform(20.0, 40.0)):
                seconds = rng.uniform(1.0, 5.0)
                hosts.partition()
                time.sleep(seconds)
                hosts.restore()
                partitions.append(seconds)

        def watch_memory() -> None:  # the last reading before the learner exits
            while run.learner.popen.poll() is None:
                rss_end.update({k: rss_mb(p.popen.pid) for k, p in procs.items() if p.popen.poll() is None})
                time.sleep(2.0)

        threads = [
            threading.Thread(target=cut, daemon=True),
            threading.Thread(target=watch_memory, daemon=True),
        ]
        for th in threads:
            th.start()
        result = run.finish(timeout_s=6 * 3600)
        stop.set()
    r: RunData = result["run"]
    rig_s = float(r.ticks.recording.t_s[-1] - r.ticks.recording.t_s[0])
    return {
        "rig_time_min": round(rig_s / 60, 1),
        "wall_min": round(result["wall_s"] / 60, 1),
        "completed": result["exit"] == 0,
        "attempts": len({e.attempt for e in events(r, "attempt_end")}),
        "planned": attempts,
        "partitions": len(partitions),
        "partition_s": [round(p, 1) for p in partitions],
        "retried": sum(1 for e in events(r, "rig_lost") if e.detail.get("call") == "play"),
        "samples_lost": missing_ticks(r),
        "published": result["published"],
        "recorded": result["recorded"],
        "rss_mb_start": {k: round(v, 1) for k, v in rss_start.items()},
        "rss_mb_end": {k: round(v, 1) for k, v in rss_end.items()},
        "restarted_by_hand": 0,
    }


def walltime(workdir: Path) -> dict[str, float]:
    """The main job's wall time on one host and on two (clean link, impaired link)."""
    out: dict[str, float] = {}
    start = time.monotonic()
    subprocess.run(
        [
            str(Path(get_package_prefix("g2p_bringup")) / "lib" / "g2p_bringup" / "bringup"),
            "--run-id",
            "onehost",
            "--no-report",
        ],
        cwd=workdir,
        check=True,
        capture_output=True,
    )
    out["one_host_s"] = round(time.monotonic() - start, 1)
    for name, impairment in (("two_hosts_clean_s", None), ("two_hosts_impaired_s", IMPAIRED)):
        with TwoHosts() as hosts:
            if impairment:
                hosts.impair(**impairment)
            g = TwoHostGraph(hosts, ROOT, workdir / name, name)
            rig = g.bringup("rig")
            start = time.monotonic()
            ws = g.bringup("ws")
            assert ws.wait(1800) == 0, ws.log()
            out[name] = round(time.monotonic() - start, 1)
            rig.stop()
    return out


def _messages_after(listener: HostProcess, t: float) -> list[float]:
    """When the listener received each message after wall time `t` (s)."""
    received = [json.loads(x)["received"] for x in listener.log().splitlines() if x[:1] == "{"]
    return [r for r in received if r > t]


def _rediscovery_once(workdir: Path, name: str, partition_s: float) -> dict[str, Any]:
    with TwoHosts() as hosts:
        g = TwoHostGraph(hosts, ROOT, workdir / f"rediscovery-{name.replace(' ', '-')}", "probe")
        peers = {"rig": hosts.ws_ip, "ws": hosts.rig_ip}
        envs = {
            h: {}
            if name == "SUBNET"
            else {"ROS_STATIC_PEERS": peers[h], "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
            for h in peers
        }
        talker = g.python("rig", PROBE, "talk", extra_env=envs["rig"])
        listener = g.python("ws", PROBE, "listen", extra_env=envs["ws"])
        listener.wait_for("the first message", 120.0, lambda: bool(_messages_after(listener, 0.0)))
        hosts.partition()
        time.sleep(partition_s)
        healed = time.time()
        hosts.restore()
        listener.wait_for(
            "a message after the partition", 120.0, lambda: bool(_messages_after(listener, healed))
        )
        first = min(_messages_after(listener, healed))
        talker.stop()
        listener.stop()
    return {"discovery": name, "partition_s": partition_s, "first_message_after_s": round(first - healed, 2)}


def rediscovery(workdir: Path, partition_s: float = 30.0) -> list[dict[str, Any]]:
    """Time from the link's return to the first message across it, after a long partition.

    The partition is longer than DDS keeps a silent peer (20 s); multicast discovery (SUBNET) against
    ROS_STATIC_PEERS.
    """
    return [_rediscovery_once(workdir, name, partition_s) for name in ("SUBNET", "static peers")]


def _placement_once(workdir: Path, where: Any, partition_s: float) -> dict[str, Any]:
    with TwoHosts() as hosts:
        g = TwoHostGraph(hosts, ROOT, workdir / f"recorder-{where}", f"recorder-{where}")
        sim = g.node("rig", "g2p_sim", "sim", *NS, "-p", "time_mode:=realtime")
        recorder = g.node(where, "g2p_recorder", "record", *NS, "-p", f"run_id:={g.run_id}")
        recorder.wait_for("recording the rig", 120.0, lambda: "/leg/joint_states" in recorder.log())
        time.sleep(5.0)
        hosts.partition()
        time.sleep(partition_s)
        hosts.restore()
        time.sleep(10.0)
        sim.stop()
        recorder.stop()
        run = load_run(g.bag)
    return {
        "recorder_on": "rig host" if where == "rig" else "workstation",
        "partition_s": partition_s,
        "published": published(sim.log()),
        "recorded": len(run.ticks.recording),
    }


def recorder_placement(workdir: Path, partition_s: float = 30.0) -> list[dict[str, Any]]:
    """Rig samples lost by a recorder beside the rig and by one on the workstation, over a long partition.

    The partition is longer than DDS keeps a silent peer (20 s); the rig, paced in real time, idles at
    baseline meanwhile.
    """
    return [_placement_once(workdir, where, partition_s) for where in ("rig", "ws")]


def main() -> None:
    """Run the chosen parts and print their figures (JSON)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "parts", nargs="*", default=["faults", "placement", "rediscovery", "walltime", "soak"]
    )
    parser.add_argument("--soak-rig-min", type=float, default=60.0, help="rig time of the soak (min)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="g2p-two-hosts-") as tmp:
        work = Path(tmp)
        report: dict[str, Any] = {}
        if "faults" in args.parts:
            report["faults"] = faults(work)
            print(json.dumps(report["faults"], indent=1), flush=True)
        if "placement" in args.parts:
            report["placement"] = recorder_placement(work)
            print(json.dumps(report["placement"], indent=1), flush=True)
        if "rediscovery" in args.parts:
            report["rediscovery"] = rediscovery(work)
            print(json.dumps(report["rediscovery"], indent=1), flush=True)
        if "walltime" in args.parts:
            report["walltime"] = walltime(work)
            print(json.dumps(report["walltime"], indent=1), flush=True)
        if "soak" in args.parts:
            report["soak"] = soak(work, args.soak_rig_min)
            print(json.dumps(report["soak"], indent=1), flush=True)
    print(json.dumps(report))


if __name__ == "__main__":
    main()
