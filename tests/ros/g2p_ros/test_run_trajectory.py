"""run_trajectory: the installed `sim` and `driver` play a trajectory in closed loop over real Fast DDS, the
inverse map evaluated every tick by the rig's own loop (g2p.rig.closed_loop), driven by a test peer."""

from __future__ import annotations

import math
import signal
from collections.abc import Callable
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
from action_msgs.msg import GoalStatus
from std_srvs.srv import Trigger

from g2p.inverse_map import random_map
from g2p.learning.attempt import plan_attempt
from g2p.learning.limit_cycle import LimitCycleConfig, attempt_kinematics
from g2p.plant import NOMINAL_TICK_HZ, Recording, TickSample
from g2p.rig import PlantRig, RigUnreachable
from g2p.rig.closed_loop import FeedbackConfig, Trajectory, TrajectoryTracker
from g2p.rig.envelope import replay
from g2p.sim import MujocoLeg, MujocoLegConfig
from g2p_interfaces.action import RunTrajectory
from g2p_interfaces.msg import MotorActivation, NamedArray
from g2p_ros.convert import map_from_weights, map_weights_arrays, recording_from_msg, trajectory_goal
from tests.ros.rig_nodes import (
    BASELINE,
    FAST_SIM_SEED,
    RigPeer,
    at_baseline,
    is_off,
    outputs,
    start_driver,
    start_sim,
)
from tests.ros.rosproc import NodeProcess, wait_until

SEED = FAST_SIM_SEED  # the fast_sim fixture's
LEAD = 3
FEATURES = np.linspace(0.3, 0.9, 10)
ZERO_GAINS = FeedbackConfig(p_gain_per_s=(0.0, 0.0), i_gain_per_s2=(0.0, 0.0), velocity_gain=(0.0, 0.0))
# Every term of the law, and a sensor delay.
FEEDBACK = FeedbackConfig(
    p_gain_per_s=(10.0, 15.0), i_gain_per_s2=(2.0, 6.0), velocity_gain=(0.3, 0.3), delay_ticks=2
)


def cycle(cycles: int) -> LimitCycleConfig:
    return LimitCycleConfig(n_cycles=cycles)


def trajectory(cycles: int, feedback: FeedbackConfig, lead: int = LEAD) -> Trajectory:
    return Trajectory(
        attempt_kinematics(FEATURES, cycle(cycles)),
        random_map(np.random.default_rng(0), n_hidden=8),
        feedback,
        lead,
    )


def sample(rec: Recording, k: int) -> TickSample:
    """Tick k of a recording as the rig's loop had it."""
    return TickSample(**{f.name: getattr(rec, f.name)[k] for f in fields(TickSample)})


def assert_tracker_decided(trajectory: Trajectory, rec: Recording, correction: np.ndarray) -> None:
    """Known answer: the core's tracker, fed the ticks the rig returned, decides exactly the activations
    the rig applied (through its safety envelope) and the corrections it reported."""
    tracker = TrajectoryTracker(trajectory, 1.0 / NOMINAL_TICK_HZ)
    decided = [tracker.next_activation(sample(rec, k - 1) if k else None) for k in range(len(rec))]
    np.testing.assert_array_equal(replay(np.array(decided), rec), rec.activation)
    np.testing.assert_array_equal(correction, tracker.correction_rad_s[: len(rec)])


def test_map_weights_round_trip_bit_for_bit() -> None:
    net = random_map(np.random.default_rng(5), n_hidden=8)
    arrays = net.to_arrays()
    named = map_weights_arrays(arrays)
    assert "format_version" in arrays and "format_version" not in [a.name for a in named]
    back = map_from_weights(named, int(arrays["format_version"][0]))
    x = attempt_kinematics(FEATURES, cycle(1))
    np.testing.assert_array_equal(back.predict(x), net.predict(x))


def test_zero_gains_play_the_open_loop_sequence_tick_for_tick(tmp_path: Path) -> None:
    # Without tick jitter, the physics after a reset repeats exactly (docs/SIMULATOR.md, "Determinism").
    sim = start_sim(tmp_path, "time_mode:=fast", f"leg.seed:={SEED}", "leg.tick_jitter_s:=0.0")
    peer = RigPeer(rig_client=True)
    try:
        peer.wait_for_rig()
        assert peer.client is not None
        traj = trajectory(3, ZERO_GAINS)
        closed = peer.client.play_trajectory(traj)
        _, open_loop = plan_attempt(FEATURES, traj.inverse_map, cycle(3), LEAD)
        peer.client.reset()
        opened = peer.client.play(open_loop)
    finally:
        peer.close()
        assert sim.stop() == 0, sim.log()
    assert len(closed.recording) == len(opened) == len(traj)
    np.testing.assert_array_equal(closed.correction_rad_s, np.zeros((len(traj), 2)))
    np.testing.assert_array_equal(closed.recording.activation, replay(open_loop, closed.recording))
    for name in (
        "activation",
        "position_rad",
        "velocity_rad_s",
        "belt_velocity_mm_s",
        "current_a",
        "power_w",
    ):
        np.testing.assert_array_equal(getattr(closed.recording, name), getattr(opened, name), err_msg=name)
    # Odometer and energy carry on across the reset: their increments are the same.
    for name in ("belt_mm", "energy_j"):
        np.testing.assert_allclose(
            np.diff(getattr(closed.recording, name), axis=0),
            np.diff(getattr(opened, name), axis=0),
            rtol=0,
            atol=1e-9,
            err_msg=name,
        )


def test_closed_loop_is_the_trackers_and_the_in_process_rigs(
    fast_sim: NodeProcess, client_peer: RigPeer
) -> None:
    peer = client_peer
    peer.wait_for_rig()
    assert peer.client is not None
    traj = trajectory(3, FEEDBACK)
    progress: list[tuple[int, int]] = []
    tracked = peer.client.play_trajectory(traj, progress=lambda done, total: progress.append((done, total)))
    rec = tracked.recording
    assert len(rec) == len(traj) and tracked.correction_rad_s.shape == (len(traj), 2)
    wait_until(lambda: bool(progress), 10.0, "feedback")  # it may arrive after the result
    assert all(total == len(traj) for _, total in progress)
    # The delay: no correction before tick 1 + delay_ticks; then the feedback acts.
    np.testing.assert_array_equal(tracked.correction_rad_s[: 1 + FEEDBACK.delay_ticks], 0.0)
    assert np.abs(tracked.correction_rad_s).max() > 0.1
    assert_tracker_decided(traj, rec, tracked.correction_rad_s)
    # The in-process reference rig on the same plant (seed, one reset since construction): the same ticks.
    leg = MujocoLeg(MujocoLegConfig(seed=SEED))
    try:
        leg.reset()
        reference = PlantRig(leg).play_trajectory(traj)
    finally:
        leg.close()
    np.testing.assert_array_equal(tracked.correction_rad_s, reference.correction_rad_s)
    for name in ("activation", "position_rad", "velocity_rad_s", "belt_mm", "current_a", "energy_j"):
        np.testing.assert_array_equal(getattr(rec, name), getattr(reference.recording, name), err_msg=name)
    np.testing.assert_allclose(rec.t_s, reference.recording.t_s, rtol=0, atol=1e-9)  # stamps are whole ns


def _named(goal: RunTrajectory.Goal, name: str) -> NamedArray:
    return next(a for a in goal.inverse_map.arrays if a.name == name)


def _set(**fields_: object) -> Callable[[RunTrajectory.Goal], None]:
    def change(goal: RunTrajectory.Goal) -> None:
        for name, value in fields_.items():
            setattr(goal, name, value)

    return change


def _wrong_version(goal: RunTrajectory.Goal) -> None:
    goal.inverse_map.format_version = 2


def _wrong_weight_shape(goal: RunTrajectory.Goal) -> None:
    w_out = _named(goal, "w_out")
    w_out.shape, w_out.data = [3, 7], np.asarray(w_out.data)[:21]


def _data_not_fitting_shape(goal: RunTrajectory.Goal) -> None:
    _named(goal, "b_hidden").data = np.zeros(5)


def _missing_array(goal: RunTrajectory.Goal) -> None:
    goal.inverse_map.arrays = [a for a in goal.inverse_map.arrays if a.name != "x_scale"]


def _nan_weight(goal: RunTrajectory.Goal) -> None:
    _named(goal, "b_out").data = np.array([0.0, math.nan, 0.0])


def _nan_desired(goal: RunTrajectory.Goal) -> None:
    desired = np.asarray(goal.desired).copy()
    desired[100] = math.nan
    goal.desired = desired


INVALID_GOALS: list[tuple[str, Callable[[RunTrajectory.Goal], None], str]] = [
    ("wrong format_version", _wrong_version, "inverse_map: format_version [2.0] is not supported"),
    ("wrong weight shape", _wrong_weight_shape, "inverse_map: w_out has shape (3, 7), expected (3, 8)"),
    (
        "data not fitting its shape",
        _data_not_fitting_shape,
        "inverse_map: b_hidden has shape [8] but 5 values",
    ),
    ("missing array", _missing_array, "inverse_map: missing ['x_scale']"),
    ("NaN weight", _nan_weight, "inverse_map: b_out has non-finite values"),
    ("NaN in desired", _nan_desired, "desired kinematics: non-finite values"),
    (
        "desired not N x 6",
        _set(desired=np.zeros(6 * 80 - 1)),
        "desired kinematics: 479 values, not a positive multiple of 6",
    ),
    (
        "empty desired",
        _set(desired=np.zeros(0)),
        "desired kinematics: 0 values, not a positive multiple of 6",
    ),
    (
        "P gain too large",
        _set(p_gain_per_s=np.array([150.0, 1.0])),
        "p_gain_per_s: must be 2 values in [0, 100]",
    ),
    (
        "negative I gain",
        _set(i_gain_per_s2=np.array([1.0, -1.0])),
        "i_gain_per_s2: must be 2 values in [0, 100]",
    ),
    (
        "NaN velocity gain",
        _set(velocity_gain=np.array([math.nan, 0.0])),
        "velocity_gain: must be 2 values in",
    ),
    ("zero integral limit", _set(integral_limit_rad_s=0.0), "integral_limit_rad_s: must be in (0, 10]"),
    (
        "correction limit too large",
        _set(correction_limit_rad_s=60.0),
        "correction_limit_rad_s: must be in (0, 50]",
    ),
    ("negative delay", _set(delay_ticks=-1), "delay_ticks: must be an integer in [0, 78]"),
    ("delay too large", _set(delay_ticks=79), "delay_ticks: must be an integer in [0, 78]"),
    ("negative lead", _set(lead_ticks=-1), "lead_ticks: must be in [0, 160), got -1"),
    ("lead too large", _set(lead_ticks=160), "lead_ticks: must be in [0, 160), got 160"),
]


def test_invalid_goals_are_rejected_and_the_log_says_why(fast_sim: NodeProcess, client_peer: RigPeer) -> None:
    peer = client_peer
    peer.wait_for_rig()
    valid = trajectory(2, FEEDBACK)
    for what, change, reason in INVALID_GOALS:
        goal = trajectory_goal(valid)
        change(goal)
        assert not peer.send_trajectory(goal).accepted, what
        line = f"run_trajectory goal rejected: {reason}"
        wait_until(lambda line=line: line in fast_sim.log(), 10.0, f"{what}: {line}")
    # Nothing was played; the rig still serves a valid goal.
    assert peer.applied() == []
    response = peer.wait(peer.send_trajectory(trajectory_goal(valid)).get_result_async(), 60.0)
    assert response.status == GoalStatus.STATUS_SUCCEEDED, response.result.message


def test_the_rig_client_refuses_a_goal_the_rig_would_reject_before_sending() -> None:
    traj = trajectory(2, FEEDBACK)
    traj.desired[7, 0] = math.nan  # the array is mutable after the trajectory was checked
    peer = RigPeer(rig_client=True, server_timeout_s=0.5)  # no rig runs: a goal sent is RigUnreachable
    try:
        assert peer.client is not None
        with pytest.raises(ValueError, match="desired kinematics: non-finite values"):
            peer.client.play_trajectory(traj)
        with pytest.raises(RigUnreachable, match="no rig serves run_trajectory"):
            peer.client.play_trajectory(trajectory(2, FEEDBACK))
    finally:
        peer.close()


def test_cancel_mid_trajectory_drops_to_baseline_within_one_tick_and_goals_exclude_each_other(
    tmp_path: Path, peer: RigPeer
) -> None:
    # At 5x real time, 100 cycles last 20 s: the checks below happen while the trajectory plays.
    sim = start_sim(tmp_path, "time_mode:=fast", f"leg.seed:={SEED}", "rig.fast_max_real_time_factor:=5.0")
    try:
        _cancel_and_exclusion(sim, peer, cycles=100)
    finally:
        assert sim.stop() == 0, sim.log()


def _cancel_and_exclusion(sim: NodeProcess, peer: RigPeer, cycles: int) -> None:
    peer.wait_for_rig()
    n = cycles * 80
    handle = peer.send_trajectory(trajectory_goal(trajectory(cycles, FEEDBACK)))
    assert handle.accepted
    wait_until(lambda: len(peer.applied()) > 100, 30.0, "the trajectory to play")
    # While it plays: no other goal of either action, no reset, and commands are ignored.
    assert not peer.play(np.full((10, 3), 0.3)).accepted
    assert not peer.send_trajectory(trajectory_goal(trajectory(1, FEEDBACK))).accepted
    refused = peer.wait(peer.reset.call_async(Trigger.Request()), 30.0)
    assert not refused.success and "in progress" in refused.message
    peer.cmd.publish(MotorActivation(activation=[0.99, 0.99, 0.99]))
    wait_until(
        lambda: "activation_cmd ignored while a run_activations or run_trajectory goal plays" in sim.log(),
        10.0,
        "the command to be ignored",
    )
    peer.wait(handle.cancel_goal_async(), 10.0)
    response = peer.wait(handle.get_result_async(), 30.0)
    assert response.status == GoalStatus.STATUS_CANCELED and response.result.message == "cancelled"
    rec = recording_from_msg(response.result.samples)
    played = len(rec)
    assert 100 < played < n
    assert len(response.result.correction_rad_s) == 2 * played
    wait_until(lambda: len(peer.applied()) > played, 10.0, "the tick after the cancel")
    applied = peer.applied()
    assert applied[:played] == rec.activation.tolist()  # the commanded 0.99 never reached the physics
    assert applied[played] == [BASELINE] * 3  # the first tick after the last played one

    # Released: a sequence plays again, and while it plays a trajectory is rejected.
    sequence = peer.play(np.full((20000, 3), 0.3))
    assert sequence.accepted
    assert not peer.send_trajectory(trajectory_goal(trajectory(1, FEEDBACK))).accepted
    peer.wait(sequence.cancel_goal_async(), 10.0)
    assert peer.wait(sequence.get_result_async(), 30.0).status == GoalStatus.STATUS_CANCELED
    assert "run_trajectory goal rejected: another sequence or a reset is in progress" in sim.log()


def test_the_driver_on_fake_devices_serves_run_trajectory(tmp_path: Path) -> None:
    state_dir = tmp_path / "fake_rig"
    driver = start_driver(tmp_path, state_dir, "autostart:=true")
    peer = RigPeer(rig_client=True)
    try:
        peer.wait_for_rig()
        assert peer.client is not None
        traj = trajectory(2, FEEDBACK)
        tracked = peer.client.play_trajectory(traj)
        rec = tracked.recording
        assert len(rec) == len(traj)
        # Paced by the hardware loop's deadlines, not by the client: no faster than the nominal rate. (Slower
        # is the machine's speed, not behaviour: a tick that overruns its deadline moves the next one on;
        # benchmarks/bench_driver.py measures the rate.)
        assert np.median(np.diff(rec.t_s)) * NOMINAL_TICK_HZ > 0.9
        assert np.abs(tracked.correction_rad_s).max() > 0.1
        assert_tracker_decided(traj, rec, tracked.correction_rad_s)
        wait_until(lambda: at_baseline(outputs(state_dir)), 10.0, "the outputs at baseline after it")

        # Shutdown while a trajectory plays: the outputs go off.
        handle = peer.send_trajectory(trajectory_goal(trajectory(20, FEEDBACK)))
        assert handle.accepted
        before = len(peer.applied())
        result = handle.get_result_async()
        wait_until(lambda: len(peer.applied()) > before + 30 or result.done(), 30.0, "the trajectory to play")
        assert not result.done(), f"the trajectory ended early: {result.result()}"
    finally:
        peer.close()
        code = driver.stop(signal.SIGINT)
    assert code == 0, driver.log()
    out = outputs(state_dir)
    assert is_off(out) and out["closed"] is True
