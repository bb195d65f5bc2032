"""TickPlant: the Gymnasium environment over the rig contract, the installed `sim` (fast time) stepped one
tick per step through activation_cmd, against the same MujocoLeg stepped in-process."""

from __future__ import annotations

import math
import time
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
from rclpy.parameter import Parameter
from std_msgs.msg import Header

from g2p.plant import FloatArray, Plant, Recording, TickSample
from g2p.rig import RigError, RigUnreachable
from g2p.rig.envelope import replay
from g2p.sim import MujocoLeg, MujocoLegConfig
from g2p_interfaces.msg import MotorActivation
from g2p_ros import contract
from g2p_ros.tick_plant import TickPlant
from tests.ros.rig_nodes import BASELINE, DEEP_QOS, start_sim
from tests.ros.rosproc import RosPeer, wait_until

SEED = 5
STEPS = 200


def actions(n: int) -> FloatArray:
    """A fixed sequence (n, 3): phase-shifted sines over 0.05..0.95, each motor below baseline at times."""
    k = np.arange(n)[:, np.newaxis]
    return 0.5 + 0.45 * np.sin(2 * np.pi * k / 40 + np.array([0.0, 2.1, 4.2]))


class Tap:
    """A plant passing through to another, keeping every sample it returns (since the last reset)."""

    def __init__(self, plant: TickPlant) -> None:
        self.plant = plant
        self.samples: list[TickSample] = []

    @property
    def tick_hz(self) -> float:
        return self.plant.tick_hz

    def reset(self) -> TickSample:
        self.samples = [self.plant.reset()]
        return self.samples[0]

    def step(self, activation: FloatArray) -> TickSample:
        self.samples.append(self.plant.step(activation))
        return self.samples[-1]

    def close(self) -> None:
        self.plant.close()


class TickPeer(RosPeer):
    """A node with a TickPlant (on simulation time, as the learner runs against the fast simulator), and
    what goes over activation_cmd and applied_activation as a third party sees it."""

    def __init__(self, sim_time: bool = True, **kwargs: float) -> None:
        super().__init__("tick_plant_test")
        self.node.set_parameters([Parameter("use_sim_time", value=sim_time)])
        self.commands: list[MotorActivation] = []
        self.applied: list[list[float]] = []
        self.node.create_subscription(MotorActivation, contract.ACTIVATION_CMD, self.commands.append, 100)
        self.node.create_subscription(
            MotorActivation, contract.APPLIED_ACTIVATION, self._on_applied, DEEP_QOS
        )
        self.plant = TickPlant(self.node, **kwargs)
        self.start()

    def _on_applied(self, msg: MotorActivation) -> None:
        if msg.header.stamp.sec or msg.header.stamp.nanosec:  # not a rest sample at time 0
            self.applied.append(list(msg.activation))

    def destroy_entities(self) -> None:
        self.plant.close()


def test_treadmill_env_over_the_sim_node_terminates_on_a_trip_and_reset_puts_the_rig_right(
    tmp_path: Path,
) -> None:
    from g2p.rl.envs import TreadmillEnv

    calibration = tmp_path / "weak_tendons.yaml"  # M1 at 1 pulls 60 N: a 40 N tendon snaps
    calibration.write_text(
        "format: g2p-leg-calibration\nversion: 1\nmodel: g2p_leg\n"
        "parameters: {tendon_rated_tension_n: 30.0, tendon_breaking_tension_n: 40.0}\n"
    )
    sim = start_sim(tmp_path, "time_mode:=fast", f"leg.calibration:={calibration}")
    peer = TickPeer()
    try:
        env = TreadmillEnv(plant=peer.plant, reset_noise_scale=0.0)
        env.reset()
        for _ in range(100):
            _, _, terminated, truncated, info = env.step(np.array([BASELINE, 1.0, BASELINE], np.float32))
            if terminated:
                break
        assert terminated and not truncated, "no trip in 100 steps"
        assert "tendon M1 snapped" in info["trip"]
        with pytest.raises(RuntimeError, match="terminated"):
            env.step(np.full(3, BASELINE, np.float32))
        env.reset()  # the rig's reset re-tendons it
        _, _, terminated, _, info = env.step(np.array([BASELINE, 0.3, BASELINE], np.float32))
        assert not terminated and "trip" not in info and peer.plant.fault == ""
        env.close()
    finally:
        peer.close()
        assert sim.stop() == 0, sim.log()


def test_treadmill_env_over_the_sim_node_steps_the_leg_tick_for_tick(tmp_path: Path) -> None:
    from g2p.rl.envs import TreadmillEnv

    sim = start_sim(tmp_path, "time_mode:=fast", f"leg.seed:={SEED}")
    peer = TickPeer()
    tap = Tap(peer.plant)
    a = actions(STEPS)
    try:
        env = TreadmillEnv(plant=tap, reset_noise_scale=0.0)
        _, info = env.reset()
        rewards = []
        for row in a:
            obs, reward, terminated, truncated, info = env.step(row)
            rewards.append(reward)
            assert not terminated and not truncated
        env.close()
    finally:
        peer.close()
        assert sim.stop() == 0, sim.log()
    rec = Recording.from_samples(tap.samples)
    assert len(rec) == 1 + STEPS
    # The reward is the belt travel of the ticks returned.
    np.testing.assert_array_equal(rewards, np.diff(rec.belt_mm))
    assert math.isclose(sum(rewards), rec.belt_travel_mm, abs_tol=1e-9)
    assert info["belt_travel_mm"] == rec.belt_travel_mm
    np.testing.assert_array_equal(obs[:2], rec.position_rad[-1])
    # The applied activations, not the commands: the command above baseline, baseline below it, through
    # the rig's safety envelope (each from the tick before: the reset's baseline tick first).
    above = a > BASELINE
    assert above.any() and (~above).any()
    applied = replay(np.maximum(a, BASELINE), rec)
    np.testing.assert_array_equal(rec.activation[1:], applied)
    np.testing.assert_array_equal(rec.activation[0], [BASELINE] * 3)  # reset's baseline tick
    # Known answer: the node's MujocoLeg (same parameters and seed) was reset at start and by the reset
    # service, then stepped once per command: the same leg in-process, stepped alike, gives the same ticks
    # bit for bit (MuJoCo is deterministic on one machine; the messages carry float64 unchanged).
    leg = MujocoLeg(MujocoLegConfig(seed=SEED))
    leg.reset()  # the rig server's start
    leg.reset()  # TickPlant.reset: the reset service, then one baseline tick
    want = Recording.from_samples([leg.step(np.full(3, BASELINE)), *(leg.step(row) for row in applied)])
    for field in fields(Recording):
        if field.name != "t_s":
            np.testing.assert_array_equal(getattr(rec, field.name), getattr(want, field.name), field.name)
    # Stamps are the plant's clock rounded to the nanosecond: one tick per step.
    np.testing.assert_allclose(rec.t_s, want.t_s, rtol=0, atol=1e-9)


def test_an_invalid_action_publishes_nothing_and_close_leaves_baseline(tmp_path: Path) -> None:
    sim = start_sim(tmp_path, "time_mode:=fast", f"leg.seed:={SEED}")
    peer = TickPeer()
    try:
        rest = peer.plant.reset()
        np.testing.assert_array_equal(rest.activation, [BASELINE] * 3)
        wait_until(lambda: len(peer.applied) >= 1 and len(peer.commands) >= 1, 10.0, "reset's baseline tick")
        commands, ticks = len(peer.commands), len(peer.applied)
        for bad in ([0.5, math.nan, 0.5], [0.5, 0.5], [math.inf, 0.2, 0.2], [[0.3, 0.3, 0.3]], []):
            with pytest.raises(ValueError):
                peer.plant.step(np.asarray(bad))
        time.sleep(0.5)  # a (wrong) command or tick would arrive within this
        assert (len(peer.commands), len(peer.applied)) == (commands, ticks)
        assert peer.applied[-1] == [BASELINE] * 3
        # The next valid command plays the next tick (lockstep), and returns it (a rise within the
        # envelope's ramp).
        sample = peer.plant.step(np.array([0.2, 0.3, 0.1]))
        np.testing.assert_array_equal(sample.activation, [0.2, 0.3, BASELINE])
        assert sample.t_s > rest.t_s
        wait_until(lambda: len(peer.applied) == ticks + 1, 10.0, "the valid command's tick")
        # close: one baseline command, which the fast rig plays as one tick.
        peer.plant.close()
        wait_until(lambda: len(peer.applied) == ticks + 2, 10.0, "close's baseline tick")
        assert peer.applied[-1] == [BASELINE] * 3
        with pytest.raises(RigError, match="closed"):
            peer.plant.step(np.full(3, 0.5))
    finally:
        peer.close()
    # A node on the wall clock against the fast rig's simulation time: told, not left waiting.
    wall = TickPeer(sim_time=False, tick_timeout_s=1.0)
    try:
        with pytest.raises(RigError, match="use_sim_time"):
            wall.plant.step(np.full(3, 0.3))
    finally:
        wall.close()
        assert sim.stop() == 0, sim.log()


@pytest.mark.slow
def test_realtime_a_command_takes_effect_a_tick_later_and_the_watchdog_drops_a_slow_policy(
    tmp_path: Path,
) -> None:
    """The rig ticks on its own at 78 Hz (as the hardware does) and decides each tick's activation at its
    start: a command arrives during the tick returned for it (the first stamped after it) and plays the
    next one, so each step's tick shows the previous step's command."""
    # The applied activations tell which command played: the soft limits, which change them near the
    # stops, the ramp, which spreads their steps, and the snatch guard, which holds a motor reeling in
    # slack at baseline, are off here (the envelope's thermal budget stays far from derating).
    sim = start_sim(
        tmp_path,
        "time_mode:=realtime",
        f"leg.seed:={SEED}",
        "rig.envelope.soft_limits:=false",
        "rig.envelope.max_step:=1.0",
        "rig.envelope.slack_guard_m:=0.05",
    )
    peer = TickPeer(sim_time=False)  # system time, as on the hardware
    commands = np.random.default_rng(1).uniform(0.2, 0.9, (100, 3))
    try:
        samples = [peer.plant.reset()]
        for command in commands:
            sent_after = time.time()
            samples.append(peer.plant.step(command))
            assert samples[-1].t_s > sent_after
        time.sleep(0.1)  # a policy slower than the watchdog (3 ticks, 38 ms)
        late = peer.plant.step(np.array([0.3, 0.3, 0.3]))
    finally:
        peer.close()
        assert sim.stop() == 0, sim.log()
    applied = np.array([s.activation for s in samples[1:]])
    # The truth, and an earlier step's: each tick applied baseline or a command sent before it.
    for k, a in enumerate(applied):
        assert a.tolist() == [BASELINE] * 3 or np.all(a == commands[: k + 1], axis=1).any(), k
    # Mostly the previous step's command (docs/RL.md gives the shares, bench_tick_plant measures them). A
    # command that needs longer than the rest of its tick to reach the rig plays a tick later still, and
    # a pause longer than the watchdog gives baseline: how often depends on the machine's load.
    previous = np.vstack([[BASELINE] * 3, commands[:-1]])
    assert np.all(applied == previous, axis=1).any()
    # Each step gets a tick of its own, later than the last (paced by the rig: bench_tick_plant measures
    # how long a step takes; a test does not fail on a slow machine).
    assert np.all(np.diff([s.t_s for s in samples]) > 0)
    # The last command was dropped by the watchdog during the pause: baseline (or, rarely, the new one).
    assert late.activation.tolist() in ([BASELINE] * 3, [0.3] * 3)


def test_no_rig_is_reported_unreachable() -> None:
    peer = TickPeer(server_timeout_s=0.5)
    assert isinstance(peer.plant, Plant)
    try:
        with pytest.raises(RigUnreachable):
            peer.plant.step(np.full(3, 0.3))
        with pytest.raises(RigUnreachable):
            peer.plant.reset()
    finally:
        peer.close()


def test_a_tick_that_never_completes_is_reported_with_the_messages_that_came() -> None:
    """A "rig" of plain publishers that answers each command on joint_states only: the step times out,
    and says which of the tick's messages came."""
    from sensor_msgs.msg import JointState

    from g2p_interfaces.msg import MotorPower, RigLimits, Treadmill

    rig = RosPeer("half_rig")
    qos = contract.SAMPLE_QOS
    joints = rig.node.create_publisher(JointState, contract.JOINT_STATES, qos)
    others = [
        rig.node.create_publisher(t, name, qos)
        for t, name in (
            (Treadmill, contract.TREADMILL),
            (MotorPower, contract.MOTOR_POWER),
            (MotorActivation, contract.APPLIED_ACTIVATION),
            (RigLimits, contract.RIG_LIMITS),
        )
    ]

    def answer(_: MotorActivation) -> None:
        joints.publish(JointState(header=Header(stamp=rig.node.get_clock().now().to_msg())))

    rig.node.create_subscription(MotorActivation, contract.ACTIVATION_CMD, answer, contract.COMMAND_QOS)
    rig.start()
    peer = TickPeer(sim_time=False, tick_timeout_s=1.0)
    try:
        with pytest.raises(RigUnreachable, match=r"of the tick stamped [0-9.]+ s only joint_states came"):
            peer.plant.step(np.full(3, 0.3))
    finally:
        peer.close()
        rig.close()
        assert others  # kept alive until here: the plant waits for a publisher on each topic
