"""The installed `sim` executable serving the rig contract over real Fast DDS, driven by a test peer."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest
from action_msgs.msg import GoalStatus
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_srvs.srv import Trigger

from g2p.plant import NOMINAL_TICK_HZ
from g2p.rig.envelope import replay
from g2p_interfaces.action import RunActivations
from g2p_interfaces.msg import MotorActivation
from g2p_ros import contract
from g2p_ros.convert import recording_from_msg
from tests.ros.rig_nodes import BASELINE, RigPeer, start_sim
from tests.ros.rosproc import NodeProcess, wait_until


def stamp_s(msg: object) -> float:
    """A message's header stamp (s)."""
    stamp = msg.header.stamp  # type: ignore[attr-defined]
    return stamp.sec + stamp.nanosec * 1e-9


def stamps_s(peer: RigPeer, topic: str) -> np.ndarray:
    """The header stamps (s) of every message received on a rig topic, in arrival order."""
    with peer.lock:
        return np.array([stamp_s(m) for m in peer.received[topic]])


def test_run_activations_gives_feedback_and_the_samples_the_topics_carried(
    fast_sim: NodeProcess, peer: RigPeer
) -> None:
    peer.wait_for_rig()
    n = 400
    activations = np.tile([0.2, 0.8, 0.3], (n, 1))
    feedback: list[object] = []
    handle = peer.play(activations, feedback)
    assert handle.accepted
    response = peer.wait(handle.get_result_async(), 60.0)
    assert response.status == GoalStatus.STATUS_SUCCEEDED
    rec = recording_from_msg(response.result.samples)
    assert len(rec) == n
    np.testing.assert_array_equal(rec.activation, replay(activations, rec))
    assert np.all(np.diff(rec.t_s) > 0)
    # M1 alone above baseline flexes the hip (Fig 1d).
    assert rec.position_rad[-1, 0] > rec.position_rad[0, 0] + math.radians(5)
    assert feedback, "no feedback arrived"
    assert all(f.feedback.ticks_total == n for f in feedback)
    # The topics carried the same ticks, the four messages of a tick sharing one stamp.
    wait_until(lambda: len(peer.applied()) >= n, 10.0, "the sequence's ticks on the topics")
    with peer.lock:
        stamps = {
            name: {(m.header.stamp.sec, m.header.stamp.nanosec) for m in msgs}
            for name, msgs in peer.received.items()
        }
        joints = {
            (m.header.stamp.sec, m.header.stamp.nanosec): m for m in peer.received[contract.JOINT_STATES]
        }
    assert (
        stamps[contract.JOINT_STATES]
        == stamps[contract.TREADMILL]
        == stamps[contract.MOTOR_POWER]
        == stamps[contract.APPLIED_ACTIVATION]
    )
    first = int(response.result.samples.stamp_ns[0])
    js = joints[divmod(first, 1_000_000_000)]
    assert list(js.name) == ["proximal", "distal"]
    np.testing.assert_array_equal(js.position, rec.position_rad[0])


def test_fast_mode_publishes_clock_every_k_ticks_and_on_the_last_tick(tmp_path: Path) -> None:
    # Paced at 5x so that the best-effort /clock reaches the peer whole.
    sim = start_sim(
        tmp_path, "time_mode:=fast", "rig.clock_period_ticks:=8", "rig.fast_max_real_time_factor:=5.0"
    )
    peer = RigPeer()
    clocks: list[int] = []  # ns
    peer.node.create_subscription(
        Clock,
        "/clock",
        lambda m: clocks.append(m.clock.sec * 1_000_000_000 + m.clock.nanosec),
        QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT),
    )
    try:
        peer.wait_for_rig()
        time.sleep(contract.DISCOVERY_SETTLE_S)
        before = len(clocks)
        handle = peer.play(np.full((203, 3), 0.3))
        result = peer.wait(handle.get_result_async(), 60.0).result
        ticks = np.asarray(result.samples.stamp_ns)
        wait_until(lambda: clocks and clocks[-1] == ticks[-1], 10.0, "the /clock of the last tick")
        during = np.array(clocks[before:])
        # Not the idle rig's repeats of its last /clock (every second) from before the play.
        during = during[during > max(clocks[:before], default=0)]
        # Every 8th tick (26 of 203, wherever the count starts) and the last: one /clock per 8 ticks.
        assert 26 <= len(during) <= 27
        assert np.isin(during, ticks).all()  # each /clock is a tick's stamp
    finally:
        peer.close()
        assert sim.stop() == 0, sim.log()


def test_fast_mode_is_deterministic_for_a_seed(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    activations = np.repeat(rng.uniform(0.15, 1.0, (20, 3)), 30, axis=0)
    results = []
    for _ in range(2):
        proc = start_sim(tmp_path, "time_mode:=fast", "leg.seed:=11")
        peer = RigPeer()
        try:
            peer.wait_for_rig()
            handle = peer.play(activations)
            results.append(peer.wait(handle.get_result_async(), 60.0).result.samples)
        finally:
            peer.close()
            assert proc.stop() == 0, proc.log()
    a, b = (recording_from_msg(r) for r in results)
    for name in ("t_s", "activation", "position_rad", "velocity_rad_s", "belt_mm", "current_a", "power_w"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_invalid_goals_are_rejected_and_a_second_goal_while_one_runs(
    fast_sim: NodeProcess, peer: RigPeer
) -> None:
    peer.wait_for_rig()
    for bad in ([0.5, math.nan, 0.5], [0.5, 0.5], [0.5, 1.5, 0.5], []):
        handle = peer.wait(peer.action.send_goal_async(RunActivations.Goal(activation=bad)), 30.0)
        assert not handle.accepted, bad
    long = peer.play(np.full((20000, 3), 0.3))
    assert long.accepted
    second = peer.play(np.full((10, 3), 0.3))
    assert not second.accepted
    peer.wait(long.cancel_goal_async(), 10.0)
    assert peer.wait(long.get_result_async(), 30.0).status == GoalStatus.STATUS_CANCELED
    assert all(
        min(a) >= BASELINE and max(a) <= 1.0 and all(math.isfinite(x) for x in a) for a in peer.applied()
    )


def test_cancel_drops_to_baseline_within_one_tick(fast_sim: NodeProcess, peer: RigPeer) -> None:
    peer.wait_for_rig()
    handle = peer.play(np.full((50000, 3), 0.9))
    wait_until(lambda: len(peer.applied()) > 100, 30.0, "the sequence to play")
    peer.wait(handle.cancel_goal_async(), 10.0)
    response = peer.wait(handle.get_result_async(), 30.0)
    played = len(response.result.samples.stamp_ns)
    assert response.status == GoalStatus.STATUS_CANCELED and played < 50000
    wait_until(lambda: len(peer.applied()) > played, 10.0, "the tick after the cancel")
    applied = peer.applied()
    assert applied[played] == [BASELINE] * 3  # the first tick after the last played one


def test_bad_commands_never_reach_the_physics_and_are_counted(fast_sim: NodeProcess, peer: RigPeer) -> None:
    peer.wait_for_rig()
    header = MotorActivation().header
    # Fast mode runs one tick per valid command (lockstep), so each valid command yields one applied tick.
    for cmd in (
        [0.3, 0.4, 0.5],
        [math.nan, 0.5, 0.5],
        [0.5, 0.5],
        [math.inf, 0.2, 0.2],
        [2.0, -1.0, 0.5],
        [0.0, 0.1, 0.2],
    ):
        peer.cmd.publish(MotorActivation(header=header, activation=cmd))
    wait_until(lambda: min(len(peer.applied()), len(peer.decided())) >= 3, 10.0, "three applied ticks")
    time.sleep(0.5)  # any further (wrong) tick would arrive within this
    # What the rig took from the commands; its envelope then ramps the steps from rest (it only lowers).
    assert peer.decided() == [[0.3, 0.4, 0.5], [1.0, BASELINE, 0.5], [BASELINE, BASELINE, 0.2]]
    assert len(peer.applied()) == 3
    assert np.all(np.array(peer.applied()) <= np.array(peer.decided()))
    # Counters are reported on /diagnostics every 78 ticks.
    handle = peer.play(np.full((80, 3), 0.2))
    peer.wait(handle.get_result_async(), 30.0)
    wait_until(lambda: bool(peer.diagnostics), 10.0, "a diagnostics message")
    values = {kv.key: kv.value for kv in peer.diagnostics[-1].status[0].values}
    assert (
        values["commands_rejected"] == "3" and values["commands_clamped"] == "1"
    )  # outside [0, 1]; sub-baseline is normal


def test_a_stale_command_is_ignored_and_a_fresh_one_applied(fast_sim: NodeProcess, peer: RigPeer) -> None:
    """A command stamped 2 s before the rig's time (held up by a network fault) never reaches the physics."""
    peer.wait_for_rig()
    samples = peer.wait(peer.play(np.full((300, 3), 0.2)).get_result_async(), 30.0).result.samples
    now_ns = int(samples.stamp_ns[-1])  # the rig's time: sim time, 3.8 s after its start
    wait_until(lambda: min(len(peer.applied()), len(peer.decided())) >= 300, 10.0, "the sequence's ticks")
    time.sleep(0.3)
    before = len(peer.decided())
    for age_ns, activation in ((2_000_000_000, [0.9, 0.9, 0.9]), (0, [0.3, 0.4, 0.5])):
        header = MotorActivation().header
        header.stamp.sec, header.stamp.nanosec = divmod(now_ns - age_ns, 1_000_000_000)
        peer.cmd.publish(MotorActivation(header=header, activation=activation))
    wait_until(lambda: len(peer.decided()) > before, 10.0, "the fresh command's tick")
    time.sleep(0.5)  # a (wrong) tick of the stale command would arrive within this
    assert peer.decided()[before:] == [[0.3, 0.4, 0.5]]
    assert "activation_cmd ignored: stamped 2.00 s ago" in fast_sim.log()


def test_reset_returns_to_rest(fast_sim: NodeProcess, peer: RigPeer) -> None:
    peer.wait_for_rig()
    first = peer.wait(peer.play(np.full((5, 3), BASELINE)).get_result_async(), 30.0).result.samples
    peer.wait(peer.play(np.tile([0.2, 0.9, 0.2], (200, 1))).get_result_async(), 30.0)
    response = peer.wait(peer.reset.call_async(Trigger.Request()), 30.0)
    assert response.success, response.message
    again = peer.wait(peer.play(np.full((5, 3), BASELINE)).get_result_async(), 30.0).result.samples
    np.testing.assert_allclose(
        recording_from_msg(again).position_rad[0], recording_from_msg(first).position_rad[0], atol=1e-3
    )


@pytest.mark.slow
def test_realtime_mode_ticks_at_78_hz_and_the_watchdog_drops_to_baseline(tmp_path: Path) -> None:
    proc = start_sim(tmp_path, "time_mode:=realtime")
    peer = RigPeer()
    try:
        peer.wait_for_rig()
        wait_until(lambda: len(peer.applied()) > 10, 30.0, "ticks to arrive")
        # In real time the stamps are the wall clock (time.time()) at the end of each tick. Count the ticks
        # stamped within a wall-clock window once all of them have arrived: the rig's own rate, whatever
        # the speed at which this process takes its messages.
        t0 = time.time()
        time.sleep(3.0)
        t1 = time.time()
        wait_until(lambda: stamps_s(peer, contract.JOINT_STATES)[-1] > t1, 30.0, "the window's ticks")
        all_stamps = stamps_s(peer, contract.JOINT_STATES)
        stamps = all_stamps[(all_stamps >= t0) & (all_stamps <= t1)]
        periods = np.diff(stamps)
        jitter = 0.0008
        assert abs(np.mean(periods) - 1 / NOMINAL_TICK_HZ) < 0.0003
        assert np.all(periods > 1 / NOMINAL_TICK_HZ - jitter - 1e-6)
        assert np.all(periods < 1 / NOMINAL_TICK_HZ + jitter + 1e-6)
        assert abs(len(stamps) / (t1 - t0) - NOMINAL_TICK_HZ) < 0.1 * NOMINAL_TICK_HZ  # wall-clock pacing
        # Watchdog: one command (a rise the envelope's ramp lets through), then silence: applied for 3
        # ticks, then baseline.
        sent = time.time()
        peer.cmd.publish(MotorActivation(activation=[0.15, 0.3, 0.15]))
        wait_until(lambda: stamps_s(peer, contract.APPLIED_ACTIVATION)[-1] > sent + 0.5, 30.0, "ticks after")
        with peer.lock:
            after = [
                list(m.activation)
                for m in peer.received[contract.APPLIED_ACTIVATION]
                if stamp_s(m) > sent - 0.1
            ]
        assert sum(a == [0.15, 0.3, 0.15] for a in after) == 3
        assert after[-1] == [BASELINE] * 3
    finally:
        peer.close()
        assert proc.stop() == 0, proc.log()


def test_the_rig_publishes_what_its_limits_did_each_tick_and_derates_a_hot_motor(
    tmp_path: Path, peer: RigPeer
) -> None:
    # Derating from 26 degC: a few seconds at activation 1 heat the windings that far.
    sim = start_sim(
        tmp_path, "time_mode:=fast", "rig.envelope.derate_start_c:=26.0", "rig.envelope.derate_full_c:=30.0"
    )
    try:
        peer.wait_for_rig()
        n = 400
        handle = peer.play(np.ones((n, 3)))
        response = peer.wait(handle.get_result_async(), 60.0)
        assert response.status == GoalStatus.STATUS_SUCCEEDED
        rec = recording_from_msg(response.result.samples)
        assert np.all(rec.activation[12:16] == 1.0)  # cold: untouched, once the ramp climbed from rest
        assert np.all(rec.activation[-1] < 1.0)  # hot: derated toward baseline
        wait_until(lambda: len(peer.received[contract.RIG_LIMITS]) >= n, 10.0, "rig_limits for each tick")
        with peer.lock:
            limits = list(peer.received[contract.RIG_LIMITS])
            applied = list(peer.received[contract.APPLIED_ACTIVATION])
        assert [stamp_s(m) for m in limits] == [stamp_s(m) for m in applied]
        last = limits[-1]
        assert list(last.commanded) == [1.0, 1.0, 1.0] and max(last.thermal_scale) < 1.0
        assert min(last.winding_estimate_c) > 26.0 and last.trip == ""
        # Co-contracted, every tendon is taut: its current holds a tension (at least baseline's 9 N), no loop.
        assert min(last.tension_estimate_n) > 9.0 and max(last.slack_loop_estimate_m) == 0.0
        np.testing.assert_allclose(
            rec.activation[-1], BASELINE + (1.0 - BASELINE) * np.array(last.thermal_scale), atol=1e-12
        )
        wait_until(lambda: bool(peer.diagnostics), 10.0, "a diagnostics message")
        values = {kv.key: kv.value for kv in peer.diagnostics[-1].status[0].values}
        assert int(values["envelope_ticks"]) > 0 and values["trip"] == ""
    finally:
        assert sim.stop() == 0, sim.log()


def test_a_tripped_rig_tells_the_client_why_and_holds_baseline_until_reset(
    tmp_path: Path, peer: RigPeer
) -> None:
    calibration = tmp_path / "weak_tendons.yaml"
    calibration.write_text(
        "format: g2p-leg-calibration\nversion: 1\nmodel: g2p_leg\n"
        "parameters: {tendon_rated_tension_n: 30.0, tendon_breaking_tension_n: 40.0}\n"
    )
    sim = start_sim(tmp_path, "time_mode:=fast", f"leg.calibration:={calibration}")
    try:
        peer.wait_for_rig()
        handle = peer.play(np.tile([0.15, 1.0, 0.15], (156, 1)))
        response = peer.wait(handle.get_result_async(), 60.0)
        assert response.status == GoalStatus.STATUS_ABORTED
        assert "tendon M1 snapped" in response.result.message
        rec = recording_from_msg(response.result.samples)
        assert len(rec) < 156
        again = peer.wait(peer.play(np.full((5, 3), 0.3)).get_result_async(), 30.0)
        assert again.status == GoalStatus.STATUS_ABORTED and "rig tripped" in again.result.message
        wait_until(lambda: bool(peer.applied()) and peer.applied()[-1] == [BASELINE] * 3, 10.0, "baseline")
        reset = peer.wait(peer.reset.call_async(Trigger.Request()), 30.0)
        assert reset.success and "put right after: tendon M1 snapped" in reset.message
        fine = peer.wait(peer.play(np.full((5, 3), 0.3)).get_result_async(), 30.0)
        assert fine.status == GoalStatus.STATUS_SUCCEEDED
    finally:
        assert sim.stop() == 0, sim.log()
