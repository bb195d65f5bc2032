"""The adversary (g2p.adversary): its patterns, what it measures, and its search, against known answers."""

from __future__ import annotations

import numpy as np
import pytest

from g2p.adversary.harm import play_harm, play_harm_in_env
from g2p.adversary.patterns import (
    DUTY_RANGE,
    HOLD_RANGE_TICKS,
    N_PARAMETERS,
    PERIOD_RANGE_S,
    RISE_RANGE,
    Pattern,
    StepSequence,
    known_attacks,
    rising_by,
    square_wave,
)
from g2p.adversary.search import LIMITS, Attack, search
from g2p.plant import NOMINAL_TICK_HZ
from g2p.rig.envelope import EnvelopeConfig
from g2p.safety import BASELINE_ACTIVATION
from g2p.validation import ConfigError

# The joint rules, the ramp and the snatch guard off (the guard as far out as the slack trip).
THERMAL_ONLY = EnvelopeConfig(soft_limits=False, max_step=1.0, slack_guard_m=EnvelopeConfig().slack_trip_m)


def test_the_unit_cube_spans_the_patterns_ranges() -> None:
    low, high = Pattern.from_unit(np.zeros(N_PARAMETERS)), Pattern.from_unit(np.ones(N_PARAMETERS))
    np.testing.assert_allclose(low.period_s, PERIOD_RANGE_S[0])
    np.testing.assert_allclose(high.period_s, PERIOD_RANGE_S[1])
    np.testing.assert_allclose([low.duty, high.duty], [np.full(3, DUTY_RANGE[0]), np.full(3, DUTY_RANGE[1])])
    np.testing.assert_allclose([low.level, high.level], [np.full(3, BASELINE_ACTIVATION), np.ones(3)])
    np.testing.assert_allclose([low.rise, high.rise], [np.full(3, RISE_RANGE[0]), np.full(3, RISE_RANGE[1])])
    with pytest.raises(ConfigError, match="x"):
        Pattern.from_unit(np.full(N_PARAMETERS, 1.5))


def test_a_pattern_is_periodic_with_edges_no_steeper_than_its_rise() -> None:
    # 0.5 s periods (39 ticks), half on; M0 steps in one tick, M1 slews 0.1 a tick, M2 starts half-way.
    pattern = Pattern(
        period_s=np.full(3, 39 / NOMINAL_TICK_HZ),
        phase=np.array([0.0, 0.0, 0.5]),
        duty=np.full(3, 0.5),
        level=np.array([1.0, 0.95, 0.6]),
        rise=np.array([1.0, 0.1, 1.0]),
    )
    a = pattern.activations(3.0, NOMINAL_TICK_HZ)
    assert a.shape == (234, 3)
    np.testing.assert_allclose(a[39:], a[:-39], atol=1e-12)  # periodic, once M1's first rise is over
    assert np.abs(np.diff(a[:, 1])).max() <= 0.1 + 1e-12
    assert a[0, 0] == 1.0 and a[0, 2] == BASELINE_ACTIVATION and a[20, 2] == 0.6
    assert a.min() >= BASELINE_ACTIVATION and a.max() <= 1.0


def test_the_known_attacks_are_points_of_the_search() -> None:
    attacks = known_attacks()
    two_phase = attacks["square_0.97hz_rising_1"].activations(3.0, NOMINAL_TICK_HZ)
    assert set(map(tuple, two_phase)) == {
        (1.0, BASELINE_ACTIVATION, 1.0),
        (BASELINE_ACTIVATION, 1.0, BASELINE_ACTIVATION),
    }
    for pattern in attacks.values():
        again = Pattern.from_unit(pattern.to_unit())
        for name in ("period_s", "phase", "duty", "level", "rise"):
            np.testing.assert_allclose(getattr(again, name), getattr(pattern, name), rtol=1e-12, atol=1e-12)


def test_rising_by_spreads_every_rise_and_lets_falls_through() -> None:
    square = square_wave(2.0, NOMINAL_TICK_HZ, 2.0, (1.0, 0.15, 1.0), (0.15, 1.0, 0.15))
    spread = rising_by(square, 0.2)
    assert np.diff(spread, axis=0).max() <= 0.2 + 1e-12
    assert np.diff(spread, axis=0).min() == pytest.approx(-0.85)
    assert spread[5, 0] == 1.0  # baseline to 1 in 5 ticks


def test_the_envelopes_joint_rules_blunt_a_square_waves_blows() -> None:
    # The 4 Hz square wave, M0 against M1, each rise spread to 0.2 a tick (measured on leg seed 0: the knee
    # entered its stop at 31 rad/s with the thermal budget alone, at 18 with the default envelope).
    pattern = rising_by(square_wave(10.0, NOMINAL_TICK_HZ, 4.0, (1, 0.15, 0.15), (0.15, 1, 0.15)), 0.2)
    bare, guarded = play_harm(pattern, THERMAL_ONLY), play_harm(pattern, EnvelopeConfig())
    assert bare.entry_speed_rad_s[1] > 25.0
    assert guarded.entry_speed_rad_s[1] < 0.8 * bare.entry_speed_rad_s[1]
    assert bare.envelope_ticks == 0 < guarded.envelope_ticks
    assert bare.fault == guarded.fault == ""


def test_baseline_does_no_harm() -> None:
    harm = play_harm(np.full((156, 3), BASELINE_ACTIVATION), EnvelopeConfig())
    assert harm.ticks == 156 and harm.fault == harm.trip == ""
    assert max(harm.entry_speed_rad_s) < 0.5  # the knee rests straight against its stop
    assert max(harm.peak_tension_n) < 15.0 and max(harm.max_slack_payout_m) < 0.001
    assert harm.score("slack", LIMITS) < 0.02


def test_a_step_sequence_loops_its_steps_each_held_its_ticks() -> None:
    x = np.linspace(0.0, 1.0, StepSequence.n_parameters)
    steps = StepSequence.from_unit(x)
    assert steps.levels[0, 0] == BASELINE_ACTIVATION  # x[0] = 0; the last of 48 levels is x[47] = 47/48
    assert steps.levels[-1, -1] == pytest.approx(BASELINE_ACTIVATION + 47 / 48 * (1 - BASELINE_ACTIVATION))
    assert steps.hold_ticks == HOLD_RANGE_TICKS[1]  # x[48] = 1
    np.testing.assert_allclose(StepSequence.from_unit(steps.to_unit()).levels, steps.levels, atol=1e-12)
    held = StepSequence(levels=steps.levels, hold_ticks=3)
    a = held.activations(1.0, NOMINAL_TICK_HZ)
    assert a.shape == (78, 3)
    np.testing.assert_array_equal(a[:6], np.repeat(steps.levels[:2], 3, axis=0))
    np.testing.assert_array_equal(a[48:78], a[:30])  # the 48-tick loop again
    with pytest.raises(ConfigError, match="hold_ticks"):
        StepSequence(levels=steps.levels, hold_ticks=0)
    with pytest.raises(ConfigError, match="levels"):
        StepSequence(levels=np.zeros((16, 3)), hold_ticks=1)


def test_the_gymnasium_path_plays_the_same_rules() -> None:
    # The environment plays each action a tick late from a noisy rest (RIG_AS_IT_RUNS), through the envelope
    # it is given: baseline does no harm there either, and its rules blunt the 4 Hz blows as the rig's do.
    rest = play_harm_in_env(np.full((78, 3), BASELINE_ACTIVATION), EnvelopeConfig())
    assert rest.ticks == 78 and rest.fault == rest.trip == "" and rest.envelope_ticks == 0
    assert max(rest.peak_tension_n) < 15.0
    pattern = rising_by(square_wave(10.0, NOMINAL_TICK_HZ, 4.0, (1, 0.15, 0.15), (0.15, 1, 0.15)), 0.2)
    bare, guarded = play_harm_in_env(pattern, THERMAL_ONLY), play_harm_in_env(pattern, EnvelopeConfig())
    assert bare.entry_speed_rad_s[1] > 25.0
    assert guarded.entry_speed_rad_s[1] < 0.8 * bare.entry_speed_rad_s[1]
    assert bare.envelope_ticks == 0 < guarded.envelope_ticks


@pytest.mark.parametrize("space", ["periodic", "steps"])
def test_a_search_is_its_seeds_and_reports_what_its_best_sequence_does(space: str) -> None:
    def tiny(seed: int) -> Attack:
        return search(THERMAL_ONLY, "impact", space, seed=seed, seconds=1.0, evaluations=20)

    first, again = tiny(0), tiny(0)
    np.testing.assert_array_equal(first.sequence.to_unit(), again.sequence.to_unit())
    assert first.harm == again.harm
    # Whole CMA-ES generations (4 + 3 ln n candidates: 12 periodic, 15 steps), after the periodic space's
    # 4 known attacks.
    assert first.evaluations == {"periodic": 4 + 2 * 12, "steps": 2 * 15}[space]
    assert play_harm(first.sequence.activations(1.0, NOMINAL_TICK_HZ), THERMAL_ONLY) == first.harm
    if space == "periodic":  # it starts from the known attacks, so it finds at least their harm
        best_known = max(
            play_harm(p.activations(1.0, NOMINAL_TICK_HZ), THERMAL_ONLY).score("impact", LIMITS)
            for p in known_attacks().values()
        )
        assert first.harm.score("impact", LIMITS) >= best_known
    with pytest.raises(ValueError, match="objective"):
        search(THERMAL_ONLY, "fun")
    with pytest.raises(ValueError, match="space"):
        search(THERMAL_ONLY, "impact", "anything")
