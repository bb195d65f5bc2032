"""The tendons seen from what the rig measures (g2p.rig.tendons): known answers, then the simulated leg's own
readings."""

from __future__ import annotations

import numpy as np
import pytest

from g2p.adversary.harm import MeteredLeg
from g2p.adversary.patterns import rising_by, square_wave
from g2p.rig.tendons import TENDON_ARMS_M, DriveRating, TendonEstimate, spool_speed_rad_s
from g2p.sim import MujocoLegConfig
from g2p.sim.motor import electrical_power_w

RATING = DriveRating()


def test_a_spools_speed_is_recovered_from_its_motors_current_and_power() -> None:
    from g2p.sim.motor import MotorConstants

    motor = MotorConstants(RATING.kt_nm_per_a, RATING.resistance_ohm, 8.0, RATING.spool_radius_m)
    current = np.array([1.2, 8.0, 3.0])
    speed = np.array([-140.0, 35.0, 0.0])  # paying out, reeling in, still
    power = electrical_power_w(current, speed, motor)
    np.testing.assert_allclose(spool_speed_rad_s(current, power, RATING), speed, atol=1e-9)
    # A motor without current (cut out): its speed is not observable, and reads 0.
    assert spool_speed_rad_s(np.zeros(3), np.ones(3), RATING).tolist() == [0.0, 0.0, 0.0]


def test_a_spool_paying_out_with_the_joints_still_slackens_its_tendon_and_fills_its_loop() -> None:
    # M1 at baseline (1.2 A, at rest stretched by its held stretch), the joints still, its spool paying
    # out at 50 rad/s (0.5 m/s) for 10 ticks of 12.8 ms: 64 mm of cable leaves it, 6.4 mm a tick, more
    # than its 2.25 mm stretch: slack from the first tick, and all 64 mm are the loop.
    estimate = TendonEstimate(RATING)
    current = np.full(3, 1.2)
    still = np.zeros(2)
    estimate.update(0.0128, current, current**2 * RATING.resistance_ohm, still)
    held = 1.2 * RATING.kt_nm_per_a / (RATING.spool_radius_m * RATING.tendon_stiffness_n_per_m)
    np.testing.assert_allclose(estimate.length_m, held)
    assert estimate.tension_n == pytest.approx(np.full(3, 9.0))
    speed = np.array([0.0, -50.0, 0.0])
    power = current**2 * RATING.resistance_ohm + RATING.kt_nm_per_a * current * speed
    loops = []
    for _ in range(10):
        estimate.update(0.0128, current, power, still)
        loops.append(estimate.loop_m[1])
    np.testing.assert_allclose(estimate.spool_speed_rad_s, speed)
    assert estimate.loop_m[0] == estimate.loop_m[2] == 0.0
    np.testing.assert_allclose(loops, 0.0064 * np.arange(1, 11), rtol=1e-9)
    assert estimate.length_m[1] < 0.0
    estimate.reset()
    assert not estimate.loop_m.any() and not estimate.length_m.any()


def test_a_joint_turning_lengthens_the_tendons_by_their_moment_arms() -> None:
    # The hip flexing at 2 rad/s with the spools still: M1 (which flexes it) slackens by 0.1 m/s, M0 and M2
    # (which extend it) lengthen by 0.05 m/s; one tick, no anchor.
    estimate = TendonEstimate(DriveRating(anchor_per_tick=1e-12))
    current = np.full(3, 1.2)
    power = current**2 * RATING.resistance_ohm
    estimate.update(0.01, current, power, np.zeros(2))
    before = estimate.length_m.copy()
    estimate.update(0.01, current, power, np.array([2.0, 0.0]))
    np.testing.assert_allclose(estimate.length_m - before, TENDON_ARMS_M[:, 0] * 2.0 * 0.01, atol=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_estimate_follows_the_simulated_tendons_through_a_violent_pattern(seed: int) -> None:
    # The 0.97 Hz two-phase square wave stepped up by 0.2 a tick, straight on the plant (no envelope):
    # stops struck at up to 14 rad/s, tendons over 90 N and 35-40 mm paid into slack loops (measured on
    # seeds 0-2). The leg's own readings (its tendons' lengths, sub-step tension peaks, cable paid out)
    # against the estimate from current, power and joint velocities: lengths within 1-2 mm RMS, the
    # tension's peak within 10 %, the loop's peak on the safe side by 10-15 mm.
    plant = MeteredLeg(MujocoLegConfig(seed=seed))
    plant.reset()
    plant.forget()
    estimate = TendonEstimate(RATING)
    true_length, length, tension, loop = [], [], [], []
    period = 1.0 / plant.tick_hz
    for row in rising_by(square_wave(10.0, plant.tick_hz, 0.97, (1, 0.15, 1), (0.15, 1, 0.15)), 0.2):
        sample = plant.step(row)
        estimate.update(period, sample.current_a, sample.power_w, sample.velocity_rad_s)
        true_length.append(np.array(plant.data.ten_length[:3]))
        length.append(estimate.length_m)
        tension.append(estimate.tension_n)
        loop.append(estimate.loop_m)
    assert plant.fault == ""
    rms = np.sqrt(np.mean((np.array(length) - np.array(true_length)) ** 2, axis=0))
    assert np.all(rms < 0.004), rms
    peak_true, peak = np.max(plant.peaks_n, axis=0), np.max(tension, axis=0)
    assert np.all(np.abs(peak - peak_true) < 0.2 * peak_true), (peak, peak_true)
    payout_true, payout = np.max(plant.payouts_m, axis=0), np.max(loop, axis=0)
    assert np.all(payout >= 0.9 * payout_true), (payout, payout_true)
    assert np.all(payout <= payout_true + 0.025), (payout, payout_true)
