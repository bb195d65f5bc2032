"""The graph on two hosts over a bad network: the rig (ROS 2 Jazzy, with the recorder beside it) in one
network namespace, the learner in another, joined by the two_hosts fixture's impairable link (g2p_twohost).

Each test is a user's run through the installed executables: `bringup --host rig|workstation`, or the
nodes one by one where one of them is killed and started again. DDS traffic stays inside the fixture's
namespaces (UDPv4 on its TUN link only).
"""

from __future__ import annotations

import signal
import subprocess
import time
from pathlib import Path

import numpy as np

from g2p.bags import bag_is_complete
from g2p.bags.dataset import RunData, load_run
from g2p.bags.reader import BagReader
from g2p.bags.resume import resume_point
from g2p.bags.ticks import header_stamp_ns
from g2p.safety import BASELINE_ACTIVATION
from g2p_twohost.graph import HostProcess, TwoHostGraph, ros_params, set_args
from g2p_twohost.hosts import TwoHosts
from tests.commands import console_script
from tests.ros.rosproc import executable
from tests.system.launched import Stopped, assert_every_tick_recorded, assert_stopped_cleanly

ROOT = Path(__file__).resolve().parents[2]
SEED = 0
# A short learning run: babbling (rig s), attempts of 4 cycles.
SHORT_RUN = {
    "learner.babbling.duration_s": "20.0",
    "cycle.n_cycles": "4",
    "search.exploitation_attempts": "4",
}
SILENCE_S = 2.0  # the learner's rig_silence_s (its default)
# Seed 0 crosses 10 mm within its first attempts (which one depends on the machine's floating point:
# torch picks its kernels by CPU), then 6 exploitation attempts.
RUN = {
    **SHORT_RUN,
    "learner.seed": str(SEED),
    "search.threshold_mm": "10.0",
    "search.exploitation_attempts": "6",
}
# Runs compared bit for bit with each other. A machine loaded enough to hold the rig's feedback back for
# the learner's default rig_silence_s (2 s) makes the learner abandon the sequence and play it again; the
# rig then plays more ticks, its tick-timing noise moves on, and from there the runs part. No link of
# these runs falls silent for 10 s.
COMPARED_RUN = {**RUN, "rig_silence_s": "10.0"}
# A rig paced by the wall clock, like the hardware: babbling and attempts take their rig time. Any
# reward crosses: 1 exploration and 2 exploitation attempts.
REALTIME_RUN = {
    **RUN,
    "learner.babbling.duration_s": "8.0",
    "search.exploitation_attempts": "2",
    "search.threshold_mm": "-1000.0",
}


def graph(two_hosts: TwoHosts, tmp_path: Path, run_id: str = "two-hosts") -> TwoHostGraph:
    return TwoHostGraph(two_hosts, ROOT, tmp_path, run_id)


def attempt_ends(run: RunData) -> list[int]:
    return [e.attempt for e in run.events if e.event == "attempt_end"]


def rewards(run: RunData) -> list[float]:
    return [e.reward_mm for e in run.events if e.event == "attempt_end"]


def events(run: RunData, name: str) -> list:
    return [e for e in run.events if e.event == name]


def first_retry(run: RunData) -> int:
    """How many attempts ended before the first sequence played again (all, when none was)."""
    lost = [e.log_time_ns for e in events(run, "rig_lost")]
    ends = [e for e in run.events if e.event == "attempt_end"]
    return sum(1 for e in ends if not lost or e.log_time_ns < lost[0])


def lost_rig(run: RunData) -> list[dict[str, object]]:
    """Why the learner abandoned sequences (its rig_lost events' details)."""
    return [e.detail for e in events(run, "rig_lost")]


def received_at(run: RunData, bag: Path, t_s: float) -> float:
    """When the recorder received the rig's joint state of `run`'s tick at `t_s` (s): wall s."""
    (k,) = np.flatnonzero(run.ticks.recording.t_s == t_s)
    stamp = run.ticks.stamps_ns[k]  # exact: a float of seconds since 1970 holds no whole nanoseconds
    with BagReader(bag) as reader:
        for m in reader.messages(["/leg/joint_states"]):
            if header_stamp_ns(m.msg.header) == stamp:
                return float(m.timestamp_ns) * 1e-9
    raise AssertionError(f"no joint state stamped {stamp} ns in {bag}")


def published_ticks(rig_log: str) -> int:
    """The rig's own count of the ticks it published (its last log line)."""
    lines = [line for line in rig_log.splitlines() if "stopped after publishing" in line]
    assert lines, f"the rig did not say how many ticks it published:\n{rig_log[-2000:]}"
    return int(lines[-1].split("stopped after publishing ")[1].split()[0])


NS = ["--ros-args", "-r", "__ns:=/leg"]


def one_host_run(tmp_path: Path, run_id: str) -> RunData:
    """The same run with the whole graph on one host (loopback), this session's distribution."""
    done = subprocess.run(
        [
            str(executable("g2p_bringup", "bringup")),
            "--run-id",
            run_id,
            "--no-report",
            *set_args(COMPARED_RUN, "learner"),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    return load_run(tmp_path / "bags" / run_id)


def rig_nodes(g: TwoHostGraph, *sim_params: str) -> tuple[HostProcess, HostProcess]:
    """The simulator and the recorder on the rig host, one process each (to kill one of them)."""
    sim = g.node("rig", "g2p_sim", "sim", *NS, *sim_params)
    recorder = g.node("rig", "g2p_recorder", "record", *NS, "-p", f"run_id:={g.run_id}")
    return sim, recorder


def learner_args(settings: dict[str, str], sim_time: bool) -> list[str]:
    """`learn`'s arguments: waiting for the recorder, with these parameters."""
    return [
        *NS,
        "-p",
        "recorder_node:=recorder",
        "-p",
        f"use_sim_time:={str(sim_time).lower()}",
        *ros_params(settings),
    ]


def learn_two_hosts(g: TwoHostGraph, rig: str, settings: dict[str, str]) -> tuple[HostProcess, HostProcess]:
    """Start both sides with bringup: the rig host first, the workstation after."""
    rig_side = g.bringup("rig", "--rig", rig)
    workstation = g.bringup("ws", "--rig", rig, *set_args(settings, "learner"))
    return rig_side, workstation


def test_a_seeded_run_over_an_impaired_link_equals_the_run_over_loopback(
    two_hosts: TwoHosts, tmp_path: Path
) -> None:
    here = one_host_run(tmp_path, "loopback")
    # Two hosts: 20 ms +- 10 ms one way and 2 % loss, both ways.
    two_hosts.impair(delay_ms=20.0, jitter_ms=10.0, loss=0.02)
    g = graph(two_hosts, tmp_path)
    rig_side, workstation = learn_two_hosts(g, "sim", COMPARED_RUN)
    assert workstation.wait(600) == 0, workstation.log()
    assert rig_side.stop() == 0, rig_side.log()

    there = load_run(g.bag)
    ends = sorted(set(attempt_ends(there)))
    assert ends == list(range(1, len(ends) + 1)) and len(ends) > 6  # exploration, then 6 exploitation
    # Bit for bit: the rig owns the timing. Up to a sequence played again, if any (COMPARED_RUN).
    same = min([first_retry(here), first_retry(there)])
    assert same > 5, f"retried sequences: loopback {lost_rig(here)}, two hosts {lost_rig(there)}"
    assert rewards(there)[:same] == rewards(here)[:same]
    for a, b in zip(here.inverse_maps[:same], there.inverse_maps[:same], strict=True):
        assert a.refinement == b.refinement
        for name, array in a.arrays.items():
            np.testing.assert_array_equal(b.arrays[name], array, err_msg=f"refinement {a.refinement} {name}")
    # Every attempt's result held every tick, and the bag holds every tick the rig published.
    for attempt in there.attempts:
        assert attempt.desired_position_rad is not None
        assert len(attempt.recording) == len(attempt.desired_position_rad)
    assert there.ticks.incomplete == 0
    rig_log = (tmp_path / "log" / "runs" / g.run_id / "sim.log").read_text()
    assert len(there.ticks.recording) == published_ticks(rig_log)
    # The traffic crossed the link (and some of it was lost on the way and resent).
    counters = two_hosts.counters()
    for direction in ("rig_to_ws", "ws_to_rig"):
        assert counters[direction]["forwarded_packets"] > 1000
        assert counters[direction]["dropped_loss_packets"] > 0


def test_a_partition_during_an_attempt_retries_it_once_the_link_returns(
    two_hosts: TwoHosts, tmp_path: Path
) -> None:
    g = graph(two_hosts, tmp_path)
    rig_side, workstation = learn_two_hosts(g, "sim_realtime", REALTIME_RUN)
    workstation.wait_for_attempt(1)
    time.sleep(1.0)  # attempt 2 plays (4 cycles, about 4 s)
    cut = time.time()
    two_hosts.partition()
    # Longer than the rest of the sequence: the rig ends it and holds baseline before the link returns.
    time.sleep(5.0)
    # The link carries packets again from somewhere inside restore() on: the learner may see the rig and
    # retry before the call returns (measured: a retry's first tick 42 ms before the return).
    healed = time.time()
    two_hosts.restore()
    assert workstation.wait(300) == 0, workstation.log()
    assert rig_side.stop() == 0, rig_side.log()

    run = load_run(g.bag)
    assert sorted(set(attempt_ends(run))) == [1, 2, 3]  # the planned attempts, each completed once
    assert len(attempt_ends(run)) == 3
    (lost,) = events(run, "rig_lost")
    (back,) = events(run, "rig_back")
    # Detected within the silence limit and a feedback period (and the learner's clock is this one's).
    assert 0.0 < lost.stamp_ns * 1e-9 - cut < SILENCE_S + 1.0
    assert back.stamp_ns * 1e-9 > healed
    # The retried attempt's data is the one played after the link returned; the lost one's is not used.
    # Each comparison stays on one clock. A tick's stamp is the rig's time of the tick, tens of ms off
    # the wall clock (measured: the first tick of attempt 2 stamped 29 ms before the learner's
    # attempt_start, which preceded it): the retry is placed on the wall clock by when the recorder
    # beside the rig received its first tick, and the lost sequence found after attempt 1's last tick.
    retried = next(a for a in run.attempts if a.attempt == 2 and a.end is not None)
    assert received_at(run, g.bag, retried.recording.t_s[0]) > healed
    point = resume_point(g.bag)
    assert point.checkpoint.attempt == 3 and len(point.attempts) == 3  # digests of the data used: verified
    # The rig held baseline once the lost sequence was over, until the retry began.
    first = next(a for a in run.attempts if a.attempt == 1)
    planned = len(retried.desired_position_rad)
    t, act = run.ticks.recording.t_s, run.ticks.recording.activation
    # The lost sequence is the retried one (same features, same map): find where the rig played it, by the
    # activations it decided (its safety envelope's braking depends on the joints' velocities).
    decided, played = run.decided_activation(run.ticks.recording), run.decided_activation(retried.recording)
    assert decided is not None and played is not None
    lost_start = next(
        k
        for k in np.flatnonzero(t > first.recording.t_s[-1])
        if np.array_equal(decided[k : k + planned], played)
    )
    assert t[lost_start] < retried.recording.t_s[0]  # the lost one, not the retry
    idle = (t > t[lost_start + planned - 1]) & (t < retried.recording.t_s[0] - 0.05)
    assert idle.sum() > 10
    np.testing.assert_array_equal(act[idle], BASELINE_ACTIVATION)
    # The rig's data has no gap: the recorder beside it kept recording through the partition.
    during = (t > cut) & (t < healed)
    assert np.all(np.diff(t[during]) < 0.05)


def test_a_partition_longer_than_the_limit_ends_the_run_cleanly_with_how_to_resume(
    two_hosts: TwoHosts, tmp_path: Path
) -> None:
    g = graph(two_hosts, tmp_path)
    # The workstation first: it waits for the rig's side and says so.
    workstation = g.bringup("ws", "--rig", "sim", *set_args({**RUN, "rig_lost_limit_s": "4.0"}, "learner"))
    workstation.wait_for(
        "the learner's wait message", 120.0, lambda: "is the rig's side up?" in workstation.log()
    )
    rig_side = g.bringup("rig", "--rig", "sim")
    workstation.wait_for_attempt(1)
    two_hosts.partition()
    code = workstation.wait(120)
    two_hosts.restore()
    assert code == 1
    assert "learn --resume" in workstation.log()
    assert rig_side.stop() == 0, rig_side.log()
    run = load_run(g.bag)
    done = sorted(set(attempt_ends(run)))
    assert done and done == list(range(1, len(done) + 1))  # every attempt done so far is in the bag
    assert resume_point(g.bag).checkpoint.attempt == done[-1]


def test_sigint_to_both_hosts_at_once_stops_every_node_cleanly(two_hosts: TwoHosts, tmp_path: Path) -> None:
    # As `ros2 launch` on each host stops its nodes (tests/system/test_stop.py on one host).
    g = graph(two_hosts, tmp_path)
    sim, recorder = rig_nodes(g, "-p", "time_mode:=realtime")
    learner = g.node("ws", "g2p_learner", "learn", *learner_args(REALTIME_RUN, sim_time=False))
    learner.wait_for_attempt(1)
    time.sleep(1.0)  # attempt 2 plays
    procs = {"sim": sim, "recorder": recorder, "learner": learner}
    for proc in procs.values():
        proc.popen.send_signal(signal.SIGINT)
    sent = time.monotonic()
    stopped: dict[str, Stopped] = {}
    while len(stopped) < len(procs) and time.monotonic() < sent + 30.0:
        for name, proc in procs.items():
            if name not in stopped and proc.popen.poll() is not None:
                stopped[name] = Stopped(proc.popen.returncode, time.monotonic() - sent)
        time.sleep(0.01)
    for name, proc in procs.items():
        assert name in stopped, f"{name} still runs 30 s after SIGINT:\n{proc.log()[-3000:]}"
        assert_stopped_cleanly(name, stopped[name], proc.log())
    assert_every_tick_recorded(g.bag, sim.log())


def test_a_rig_killed_and_restarted_mid_run_is_waited_for_and_the_run_completes(
    two_hosts: TwoHosts, tmp_path: Path
) -> None:
    g = graph(two_hosts, tmp_path)
    sim, recorder = rig_nodes(g, "-p", "time_mode:=realtime")
    learner = g.node("ws", "g2p_learner", "learn", *learner_args(REALTIME_RUN, sim_time=False))
    learner.wait_for_attempt(1)
    time.sleep(1.0)
    sim.stop(signal.SIGKILL)
    time.sleep(1.0)
    sim = g.node("rig", "g2p_sim", "sim", *NS, "-p", "time_mode:=realtime")
    assert learner.wait(300) == 0, learner.log()
    assert "rig lost" in learner.log() and "rig back" in learner.log()
    sim.stop()
    recorder.stop()
    run = load_run(g.bag)
    assert sorted(set(attempt_ends(run))) == [1, 2, 3]


def test_a_learner_killed_during_exploitation_resumes_bit_for_bit_from_the_bag(
    two_hosts: TwoHosts, tmp_path: Path
) -> None:
    uninterrupted = one_host_run(tmp_path, "reference")  # the answer
    g = graph(two_hosts, tmp_path)
    # A fast rig slowed to 3x real time, so that the kill falls inside an attempt.
    sim, recorder = rig_nodes(g, "-p", "time_mode:=fast", "-p", "rig.fast_max_real_time_factor:=3.0")
    learn_args = learner_args(COMPARED_RUN, sim_time=True)
    learner = g.node("ws", "g2p_learner", "learn", *learn_args)
    learner.wait_for_attempt(6)  # exploitation since attempt 4
    time.sleep(0.5)
    learner.stop(signal.SIGKILL)
    resumed = g.node("ws", "g2p_learner", "learn", "--resume", str(g.bag), *learn_args)
    assert resumed.wait(300) == 0, resumed.log()
    sim.stop()
    recorder.stop()

    run = load_run(g.bag)
    checkpoints = events(run, "checkpoint")
    restart = next(e for e in events(run, "run_start") if "resumed_from" in e.detail)
    k = restart.detail["resumed_from"]["attempt"]
    assert k >= 6
    # In the order the recorder received them (the first learner's events, then the second's).
    before = next(e for e in checkpoints if e.attempt == k and e.log_time_ns < restart.log_time_ns)
    after = next(e for e in checkpoints if e.attempt == k and e.log_time_ns > restart.log_time_ns)
    assert after.detail["checkpoint"] == before.detail["checkpoint"]  # bit for bit (exact JSON floats)
    ends = sorted(set(attempt_ends(run)))
    assert ends == list(range(1, len(ends) + 1)) and len(ends) > k  # the run completes after the resume
    assert all(e.run_id == g.run_id for e in run.events if e.run_id)  # the continuation is the same run
    # The uninterrupted run is the answer as long as neither played a sequence again (COMPARED_RUN).
    assert min(first_retry(run), first_retry(uninterrupted)) > k, (
        f"retried sequences: resumed run {lost_rig(run)}, reference {lost_rig(uninterrupted)}"
    )
    reference_k = next(e for e in events(uninterrupted, "checkpoint") if e.attempt == k)
    assert after.detail["checkpoint"] == reference_k.detail["checkpoint"]

    # The next proposal is the uninterrupted run's, and the run completes with the planned attempts.
    def features(data: RunData, n: int) -> list[float]:
        ends = [e for e in events(data, "attempt_end") if e.attempt == n]
        return ends[-1].features.tolist()

    assert features(run, k + 1) == features(uninterrupted, k + 1)
    assert ends == sorted(set(attempt_ends(uninterrupted)))


def test_a_recorder_killed_mid_run_leaves_a_recoverable_bag_and_an_undisturbed_run(
    two_hosts: TwoHosts, tmp_path: Path
) -> None:
    g = graph(two_hosts, tmp_path)
    sim, recorder = rig_nodes(g, "-p", "time_mode:=fast", "-p", "rig.fast_max_real_time_factor:=5.0")
    learner = g.node("ws", "g2p_learner", "learn", *learner_args(RUN, sim_time=True))
    learner.wait_for_attempt(2)
    # Attempts here last under a second of wall time: wait out the recorder's chunk_period_s (1 s), the
    # most a killed recorder may lose, so that attempt 1's end is on disk whatever the machine's pace.
    time.sleep(2.0)
    recorder.stop(signal.SIGKILL)
    assert learner.wait(300) == 0, learner.log()  # the run does not need its recorder once started
    assert learner.attempts_done() >= 5
    sim.stop()
    assert not bag_is_complete(g.bag)
    recovered = subprocess.run(
        [str(console_script("g2p-recover-bag")), str(g.bag)], capture_output=True, text=True, timeout=120
    )
    assert recovered.returncode == 0, recovered.stderr
    run = load_run(g.bag)
    assert run.babbling_segments and attempt_ends(run)[:1] == [1]
    assert "/leg/learner/config" in run.configs  # the latched configurations survived
