"""The rig's safety envelope (g2p.rig.envelope) and the tick loop that applies it, against known answers."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from g2p.learning.babbling import BabblingConfig
from g2p.learning.experiments import TreadmillRun
from g2p.learning.learner import Learner, LearnerConfig
from g2p.learning.limit_cycle import LimitCycleConfig
from g2p.learning.search import SearchConfig
from g2p.plant import Recording, TickSample, first_order_temperature, hold
from g2p.rig import PlantRig, RigError
from g2p.rig.envelope import (
    JOINT_STOPS_RAD,
    EnvelopeConfig,
    SafetyEnvelope,
    WindingRating,
    fastest_stop_entries,
    stop_entry_speeds,
)
from g2p.rig.tick_loop import CommandOutcome, Job, Pacing, TickLoop, TickLoopConfig
from g2p.safety import BASELINE_ACTIVATION
from g2p.sim import AIR_CARRIAGE_HEIGHT_M, MujocoLeg, MujocoLegConfig
from g2p.validation import ConfigError

ONES = np.ones(3)


def measured(t_s: float, activation: np.ndarray) -> TickSample:
    """A tick that ended at `t_s` with `activation` applied, the joints still, the spools still."""
    current = np.asarray(activation, dtype=np.float64) * WindingRating().max_current_a
    return TickSample(
        t_s=t_s,
        activation=np.asarray(activation, dtype=np.float64),
        position_rad=np.zeros(2),
        velocity_rad_s=np.zeros(2),
        belt_mm=0.0,
        belt_velocity_mm_s=0.0,
        current_a=current,
        power_w=current**2 * WindingRating().resistance_ohm,
        energy_j=np.zeros(3),
    )


def test_the_thermal_estimate_is_the_first_order_solution_of_the_regulated_current() -> None:
    envelope = SafetyEnvelope()
    w = WindingRating()
    envelope.observe(measured(0.0, np.zeros(3)))
    for k in range(1, 101):
        envelope.observe(measured(0.1 * k, np.array([0.0, 0.5, 1.0])))  # 0, 4 and 8 A
    expected = w.ambient_c + np.array([0.0, 16.0, 64.0]) * w.resistance_ohm * w.thermal_resistance_k_per_w
    expected = w.ambient_c + (expected - w.ambient_c) * (1.0 - math.exp(-10.0 / w.time_constant_s))
    np.testing.assert_allclose(envelope.winding_c, expected, rtol=1e-12)
    np.testing.assert_allclose(
        first_order_temperature(np.array([80.0]), np.zeros(1), 1e9, 2.5, 60.0, 25.0), [25.0]
    )


def calibration_file(tmp_path: Path, parameters: dict[str, object]) -> str:
    """A calibration file (g2p-calibrate's format) with `parameters`; its path."""
    path = tmp_path / "calib.yaml"
    doc = {"format": "g2p-leg-calibration", "version": 1, "model": "g2p_leg", "parameters": parameters}
    path.write_text(yaml.safe_dump(doc))
    return str(path)


def test_the_envelope_takes_its_motor_constants_from_the_rigs_calibration(tmp_path: Path) -> None:
    # The thermal estimate's rise is I^2 R: with the winding's calibrated 1.2 ohm, twice the rated 0.6's.
    path = calibration_file(
        tmp_path, {"motor_resistance_ohm": 1.2, "motor_kt_nm_per_a": 0.05, "belt_drag_n": 4.0}
    )
    rated, calibrated = SafetyEnvelope(), SafetyEnvelope(EnvelopeConfig(calibration=path))
    assert calibrated.config.winding.resistance_ohm == calibrated.config.drive.resistance_ohm == 1.2
    assert calibrated.config.drive.kt_nm_per_a == 0.05 and calibrated.tendons.rating.kt_nm_per_a == 0.05
    assert calibrated.config.calibration == ""  # applied
    assert replace(calibrated.config, drive=rated.config.drive, winding=rated.config.winding) == rated.config
    for envelope in (rated, calibrated):
        envelope.observe(measured(0.0, np.zeros(3)))
        envelope.observe(measured(10.0, ONES))
    ambient = WindingRating().ambient_c
    np.testing.assert_allclose(calibrated.winding_c - ambient, 2.0 * (rated.winding_c - ambient), rtol=1e-12)
    # The packaged paper-like rig calibrates the belt and the foot only: the rated constants stay.
    assert SafetyEnvelope(EnvelopeConfig(calibration="paper")).config == rated.config


@pytest.mark.parametrize(
    ("parameters", "message"),
    [
        ({"motor_kt_nm_per_a": "fast"}, "motor_kt_nm_per_a must be a number"),
        ({"motor_resistance_ohm": -1.0}, "resistance_ohm: must be finite and > 0"),
    ],
)
def test_a_bad_calibration_is_refused_naming_it(
    tmp_path: Path, parameters: dict[str, object], message: str
) -> None:
    with pytest.raises(ConfigError, match=rf"calibration: .*{message}"):
        EnvelopeConfig(calibration=calibration_file(tmp_path, parameters))
    with pytest.raises(ConfigError, match=r"calibration: no calibration file 'nope\.yaml'"):
        EnvelopeConfig(calibration="nope.yaml")


def test_a_hot_motor_is_derated_toward_baseline_and_trips_only_at_its_cut_out() -> None:
    config = EnvelopeConfig(max_step=1.0)  # no ramp from rest: the thermal scale alone
    envelope = SafetyEnvelope(config)
    midway = 0.5 * (config.derate_start_c + config.derate_full_c)
    envelope.winding_c = np.array([25.0, midway, config.derate_full_c])
    action = envelope.limit(ONES, None, None)
    half = BASELINE_ACTIVATION + 0.5 * (1.0 - BASELINE_ACTIVATION)
    np.testing.assert_allclose(action.applied, [1.0, half, BASELINE_ACTIVATION])
    np.testing.assert_allclose(action.thermal_scale, [1.0, 0.5, 0.0])
    assert action.acted and envelope.trip == ""
    envelope.winding_c[0] = config.trip_c
    assert "M0's winding" in envelope.trip


def test_soft_limits_scale_the_drivers_of_a_joint_flying_at_its_stop() -> None:
    envelope = SafetyEnvelope(EnvelopeConfig(soft_limits=True, max_step=1.0))  # no ramp from rest
    # The knee 0.2 rad from its upper stop (0), extending at 10 rad/s: M0 extends it, M2 flexes it.
    a = np.array([0.8, 0.5, 0.2])
    action = envelope.limit(a, np.array([0.0, -0.2]), np.array([0.0, 10.0]))
    assert action.applied[0] < a[0]  # the driver, scaled down
    assert action.applied[1] == a[1]  # M1 does not turn the knee
    assert action.applied[2] == a[2]  # the antagonist, untouched
    # Far from the stops, or slow, or moving away: untouched.
    for q, v in (([0.0, -0.9], [0.0, 3.0]), ([0.0, -0.2], [0.0, 1.0]), ([0.0, -0.2], [0.0, -5.0])):
        assert not envelope.limit(a, np.array(q), np.array(v)).acted
    # No motor above baseline: the rig's own baseline (idle, after a cancel or a fault) is left alone.
    assert not envelope.limit(
        np.full(3, BASELINE_ACTIVATION), np.array([0.0, -0.2]), np.array([0.0, 10.0])
    ).acted
    off = SafetyEnvelope(EnvelopeConfig(soft_limits=False, max_step=1.0))
    assert not off.limit(a, np.array([0.0, -0.2]), np.array([0.0, 10.0])).acted


def test_the_ramp_spreads_a_step_lets_a_smooth_rise_and_a_fall_through() -> None:
    cfg = EnvelopeConfig(soft_limits=False)
    envelope = SafetyEnvelope(cfg)
    base = np.full(3, BASELINE_ACTIVATION)
    # A rig starts at baseline: its first command is ramped from there.
    np.testing.assert_allclose(envelope.limit(ONES, None, None).applied, base + cfg.max_step)
    envelope = SafetyEnvelope(cfg)
    t = 0.0

    def tick(command: np.ndarray) -> np.ndarray:
        nonlocal t
        applied = envelope.limit(command, None, None).applied
        t += 0.0128
        envelope.observe(measured(t, applied))
        return applied

    tick(base)
    # A step of M0 from baseline to 1: max_step in the first tick, then ramp_per_tick until it is there.
    # M1's step of 0.15 is within max_step; M2 stays.
    step = np.array([1.0, BASELINE_ACTIVATION + 0.15, BASELINE_ACTIVATION])
    climb = [tick(step) for _ in range(20)]
    expected_m0 = np.minimum(BASELINE_ACTIVATION + cfg.max_step + cfg.ramp_per_tick * np.arange(20), 1.0)
    np.testing.assert_allclose([a[0] for a in climb], expected_m0, rtol=1e-12)
    assert all(a[1] == step[1] and a[2] == step[2] for a in climb)
    # A fall to baseline (a cancel, a stop) is applied at once.
    np.testing.assert_array_equal(tick(base), base)
    # A rise at the sustained slope passes untouched, however long.
    for k in range(1, 15):
        smooth = base + np.array([cfg.ramp_per_tick * k, 0.0, 0.0])
        action = envelope.limit(smooth, None, None)
        assert not action.acted
        t += 0.0128
        envelope.observe(measured(t, action.applied))


def test_no_sequence_of_commands_rises_faster_than_the_ramp() -> None:
    # The walk-around of a ramp that caps one tick's rise: rises of max_step every tick, and random
    # commands of every kind (stair steps, small rises, dips that would refill a per-step cap).
    cfg = EnvelopeConfig(soft_limits=False)
    rng = np.random.default_rng(0)
    walk = np.minimum(BASELINE_ACTIVATION + cfg.max_step * np.arange(1, 41), 1.0)
    attacks = [np.tile(walk[:, None], (1, 3))]
    attacks += [rng.uniform(BASELINE_ACTIVATION, 1.0, (400, 3)) for _ in range(5)]
    attacks += [np.cumsum(rng.choice([-0.3, 0.2, 0.2], (400, 3)), axis=0).clip(BASELINE_ACTIVATION, 1.0)]
    for commands in attacks:
        envelope = SafetyEnvelope(cfg)
        applied = []
        for k, command in enumerate(commands):
            a = envelope.limit(command, None, None).applied
            envelope.observe(measured(0.0128 * (k + 1), a))
            applied.append(a)
        a = np.vstack([np.full(3, BASELINE_ACTIVATION), applied])
        for n in range(1, 30):  # every window of n ticks
            rise = (a[n:] - a[:-n]).max()
            assert rise <= cfg.max_step + cfg.ramp_per_tick * (n - 1) + 1e-12, (n, rise)
    # Baseline to 1 by rises of max_step: 12 ticks, as a stair step.
    envelope = SafetyEnvelope(cfg)
    for k, command in enumerate(walk):
        a = envelope.limit(np.full(3, command), None, None).applied
        envelope.observe(measured(0.0128 * (k + 1), a))
        if a[0] >= 1.0:
            break
    assert k + 1 == 12


def test_garbage_at_activation_1_for_a_minute_cannot_overheat_a_motor() -> None:
    # What `ros2 topic pub` at 1 does to a rig: one command per tick, on the rig's own loop, for two
    # minutes: long enough for the same garbage to cut the raw plant's drivers out (in one it does not).
    seconds = 120
    plant = MujocoLeg(MujocoLegConfig(carriage_height_m=AIR_CARRIAGE_HEIGHT_M))
    loop = TickLoop(plant, Pacing.ON_DEMAND)
    loop.start(plant.reset().t_s, threaded=False)
    hottest = 0.0
    for _ in range(round(seconds * plant.tick_hz)):
        assert loop.command([1.0, 1.0, 1.0]) is CommandOutcome.APPLIED
        loop.tick()
        hottest = max(hottest, float(np.max(plant.winding_temperature_c)))
    assert plant.fault == "" and loop.trip == ""
    assert hottest < plant.limits.winding_cutout_c
    assert loop.counters.envelope_ticks > 0
    # Raw, the same two minutes cut the drivers out.
    raw = MujocoLeg(MujocoLegConfig(carriage_height_m=AIR_CARRIAGE_HEIGHT_M))
    hold(raw, ONES, round(seconds * raw.tick_hz))
    assert "cut out" in raw.fault


def test_a_trip_ends_the_job_with_its_reason_and_holds_baseline_until_a_reset() -> None:
    plant = MujocoLeg(MujocoLegConfig(carriage_height_m=AIR_CARRIAGE_HEIGHT_M))
    plant.limits = replace(plant.limits, tendon_rated_n=30.0, tendon_breaking_n=40.0)
    rig = PlantRig(plant)
    rig.reset()
    with pytest.raises(RigError, match="tendon M1 snapped"):
        rig.play(np.tile([0.15, 1.0, 0.15], (78, 1)))
    loop = rig._loop
    assert "snapped" in loop.trip and loop.counters.trips == 1
    job = Job(activations=np.tile([0.15, 0.3, 0.15], (5, 1)))
    loop.play(job)
    assert "rig tripped" in job.error and job.done.is_set()
    assert loop.command([1.0, 1.0, 1.0]) is CommandOutcome.TRIPPED
    loop.tick()  # a lockstep client still gets its tick, at baseline
    rig.reset()
    assert loop.trip == "" and plant.fault == ""
    recording = rig.play(np.tile([0.15, 0.3, 0.15], (5, 1)))
    np.testing.assert_allclose(recording.activation[-1], [0.15, 0.3, 0.15])


def _square_wave(seconds: float, tick_hz: float, hz: float = 0.97) -> np.ndarray:
    """The slamming pattern: M0 and M2 at 1 with M1 at baseline for half a period, then the reverse."""
    t = np.arange(round(seconds * tick_hz)) / tick_hz
    first = (np.floor(t * hz * 2) % 2 == 0)[:, None]
    return np.where(first, [1.0, BASELINE_ACTIVATION, 1.0], [BASELINE_ACTIVATION, 1.0, BASELINE_ACTIVATION])


def _knee_entries(envelope: EnvelopeConfig, activations: np.ndarray) -> tuple[np.ndarray, int]:
    rig = PlantRig(MujocoLeg(MujocoLegConfig()), config=TickLoopConfig(envelope=envelope))
    rig.reset()
    rec = rig.play(activations)
    speeds = stop_entry_speeds(rec.position_rad[:, 1], rec.velocity_rad_s[:, 1], JOINT_STOPS_RAD[1])
    return speeds, rig.counters.envelope_ticks


def test_the_fastest_stop_entries_of_a_recording() -> None:
    # Known answer: the knee enters its upper stop (0 rad) at 5 rad/s, leaves, enters again at 3 rad/s;
    # the hip stays mid-range.
    knee = np.array([-0.5, -0.1, -0.01, -0.2, -0.015, -0.3])
    knee_velocity = np.array([0.0, 4.0, 5.0, -2.0, 3.0, -1.0])
    samples = [
        replace(
            measured(0.01 * k, ONES * BASELINE_ACTIVATION),
            position_rad=np.array([0.2, q]),
            velocity_rad_s=np.array([1.0, v]),
        )
        for k, (q, v) in enumerate(zip(knee, knee_velocity, strict=True))
    ]
    np.testing.assert_array_equal(fastest_stop_entries(Recording.from_samples(samples)), [0.0, 5.0])


def test_a_knee_slammed_into_its_stop_is_slowed() -> None:
    # The two-phase square wave for 30 s: its slams build up over the first 15 s (docs/RESULTS.md, "The rig's
    # limits": over six seeds of the simulated rig, knee p95 15.3-21.1 rad/s and max 21.1-30.7 without the
    # envelope's joint rules, p95 6.2-8.6 and max 7.6-11.9 with them; the goal is p95 <= 10). The bounds
    # hold on every one of those seeds: a CPU whose float sums differ plays this seed like another.
    square = _square_wave(30.0, MujocoLegConfig().tick_hz)
    raw, _ = _knee_entries(EnvelopeConfig(soft_limits=False, max_step=1.0), square)
    limited, changed = _knee_entries(EnvelopeConfig(), square)
    assert len(raw) >= 20 and len(limited) >= 20 and changed > 0
    assert np.percentile(limited, 95) <= 10.0 and np.percentile(raw, 95) > 12.0
    assert np.max(limited) < 0.7 * np.max(raw)


def test_babbling_and_a_short_g2p_run_pass_the_envelope_without_a_trip() -> None:
    # The envelope changes babbling's ticks mostly by the ramp's climb after a stair step, and the attempts'
    # by the ramp's sustained slope (a limit cycle rises up to 0.17 a tick; the bucket refills 0.06 a tick).
    # This short run's 60 s of babbling: 13.8 %; its 3 short attempts: 29 % (docs/SIMULATOR.md, "The safety
    # envelope", for whole runs). The bounds leave room for that, not for more; no rule trips on a learner.
    learner = Learner(LearnerConfig(babbling=BabblingConfig(duration_s=60.0)))
    rig = PlantRig(MujocoLeg(MujocoLegConfig()))
    learner.babble(rig)
    babbled, babbling_changed = rig.counters.ticks, rig.counters.envelope_ticks
    assert babbling_changed / babbled < 0.16
    run = TreadmillRun(
        learner,
        SearchConfig(max_exploration_attempts=3, exploitation_attempts=3),
        LimitCycleConfig(n_cycles=5),
    )
    while not run.finished:
        run.next_attempt(rig)
    attempts = rig.counters.ticks - babbled
    assert attempts > 0 and (rig.counters.envelope_ticks - babbling_changed) / attempts < 0.35
    assert rig.counters.trips == 0


def test_a_spool_paying_into_its_slack_tendon_trips_the_rig_before_it_derails() -> None:
    # M1's spool paying out at 50 rad/s (0.5 m/s: 6.4 mm a tick) with the joints still: its tendon goes
    # slack at once and the loop grows 6.4 mm a tick; the envelope trips past slack_trip_m, naming it.
    cfg = EnvelopeConfig()
    envelope = SafetyEnvelope(cfg)
    current = np.full(3, BASELINE_ACTIVATION * WindingRating().max_current_a)
    speed = np.array([0.0, -50.0, 0.0])
    power = current**2 * WindingRating().resistance_ohm + cfg.drive.kt_nm_per_a * current * speed
    ticks = 0
    envelope.observe(replace(measured(0.0, np.full(3, BASELINE_ACTIVATION)), current_a=current))
    while not envelope.trip:
        ticks += 1
        sample = measured(0.0128 * ticks, np.full(3, BASELINE_ACTIVATION))
        envelope.observe(replace(sample, current_a=current, power_w=power))
    assert ticks == math.floor(cfg.slack_trip_m / 0.0064) + 1  # 8 ticks: 51.2 mm
    assert envelope.trip.startswith("tendon M1: an estimated 51 mm of cable paid into its slack loop")
    # A reset's sample starts the estimate again: the trip clears with it.
    envelope.observe(measured(1.0, np.full(3, BASELINE_ACTIVATION)), at_rest=True)
    assert envelope.trip == ""


def test_a_motor_reeling_in_a_slack_loop_is_held_at_baseline_until_its_tendon_is_taut() -> None:
    # M1's spool pays out 6.4 mm a tick for 2 ticks (a 12.8 mm loop, past the 3 mm guard), then reels in at
    # 50 rad/s: while the loop lasts M1 is held at baseline, M0 and M2 are not; once it is taken up, M1's
    # command passes again (through the ramp, from baseline).
    cfg = EnvelopeConfig(soft_limits=False)
    envelope = SafetyEnvelope(cfg)
    command = np.array([0.3, 0.9, 0.3])
    current = np.full(3, BASELINE_ACTIVATION * WindingRating().max_current_a)

    def tick(k: int, speed: float) -> np.ndarray:
        applied = envelope.limit(command, np.zeros(2), np.zeros(2)).applied
        spools = np.array([0.0, speed, 0.0])
        power = current**2 * WindingRating().resistance_ohm + cfg.drive.kt_nm_per_a * current * spools
        envelope.observe(replace(measured(0.0128 * k, applied), current_a=current, power_w=power))
        return applied

    envelope.observe(replace(measured(0.0, np.full(3, BASELINE_ACTIVATION)), current_a=current))
    assert tick(1, -50.0)[1] > BASELINE_ACTIVATION  # taut so far: the ramp's first 0.2
    tick(2, -50.0)
    assert envelope.tendons.loop_m[1] == pytest.approx(0.0128)
    held = tick(3, 50.0)
    assert held[1] == BASELINE_ACTIVATION and held[0] > BASELINE_ACTIVATION and held[2] > BASELINE_ACTIVATION
    k = 3
    while envelope.tendons.loop_m[1] > cfg.slack_guard_m:
        k += 1
        assert tick(k, 50.0)[1] == BASELINE_ACTIVATION
    assert tick(k + 1, 0.0)[1] == BASELINE_ACTIVATION + cfg.max_step
