"""Property-based tests of the safety envelope: no command sequence breaks its own invariants.

Hypothesis draws command sequences of every kind (out of range, stair steps, rises just under a step,
dips) with the joint states, tick lengths and motor readings a rig could report, and checks each tick's
applied activations. The examples are derandomized (the same ones on every run and machine) and nothing is
stored between runs.
"""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from g2p.plant import TickSample
from g2p.rig.envelope import EnvelopeConfig, SafetyEnvelope, WindingRating
from g2p.safety import BASELINE_ACTIVATION

CONFIG = EnvelopeConfig()
TICKS = 60

finite = {"allow_nan": False, "allow_infinity": False}
commands = arrays(np.float64, (TICKS, 3), elements=st.floats(-0.5, 1.5, **finite))
positions = arrays(np.float64, (TICKS, 2), elements=st.floats(-2.0, 1.2, **finite))
velocities = arrays(np.float64, (TICKS, 2), elements=st.floats(-40.0, 40.0, **finite))
tick_lengths = arrays(np.float64, (TICKS,), elements=st.floats(0.004, 0.03, **finite))
spool_speeds = arrays(np.float64, (TICKS, 3), elements=st.floats(-150.0, 150.0, **finite))

PROPERTY = settings(
    max_examples=150,
    deadline=None,  # a slow machine is not a failure
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow],
)


def observe(
    envelope: SafetyEnvelope,
    t_s: float,
    applied: np.ndarray,
    position: np.ndarray,
    velocity: np.ndarray,
    spool_speed: np.ndarray,
) -> None:
    """Let `envelope` observe a tick that ended at `t_s` with `applied`, its motors' readings those of
    spools turning at `spool_speed` (rad/s) under the current the drivers regulate."""
    rating = envelope.config.drive
    current = applied * WindingRating().max_current_a
    envelope.observe(
        TickSample(
            t_s=t_s,
            activation=applied,
            position_rad=position,
            velocity_rad_s=velocity,
            belt_mm=0.0,
            belt_velocity_mm_s=0.0,
            current_a=current,
            power_w=current**2 * rating.resistance_ohm + rating.kt_nm_per_a * current * spool_speed,
            energy_j=np.zeros(3),
        )
    )


def play(
    command: np.ndarray,
    position: np.ndarray,
    velocity: np.ndarray,
    tick_s: np.ndarray,
    spool_speed: np.ndarray,
) -> np.ndarray:
    """Each tick's applied activation through one envelope, shape (TICKS, 3)."""
    envelope = SafetyEnvelope(CONFIG)
    applied = []
    t_s = 0.0
    for k in range(TICKS):
        limited = envelope.limit(command[k], position[k], velocity[k]).applied
        applied.append(limited)
        t_s += float(tick_s[k])
        observe(envelope, t_s, limited, position[k], velocity[k], spool_speed[k])
    return np.array(applied)


@PROPERTY
@given(commands, positions, velocities, tick_lengths, spool_speeds)
def test_applied_activations_stay_in_range_and_never_exceed_the_command(
    command: np.ndarray,
    position: np.ndarray,
    velocity: np.ndarray,
    tick_s: np.ndarray,
    spool_speed: np.ndarray,
) -> None:
    applied = play(command, position, velocity, tick_s, spool_speed)
    assert np.all(np.isfinite(applied))
    assert np.all(applied >= BASELINE_ACTIVATION) and np.all(applied <= 1.0)
    # The envelope only lowers: never above the command as the plant would take it (clipped to [base, 1]).
    assert np.all(applied <= np.clip(command, BASELINE_ACTIVATION, 1.0))


@PROPERTY
@given(commands, positions, velocities, tick_lengths, spool_speeds)
def test_no_window_of_ticks_rises_faster_than_the_ramp(
    command: np.ndarray,
    position: np.ndarray,
    velocity: np.ndarray,
    tick_s: np.ndarray,
    spool_speed: np.ndarray,
) -> None:
    applied = play(command, position, velocity, tick_s, spool_speed)
    a = np.vstack([np.full(3, BASELINE_ACTIVATION), applied])  # a rig starts at baseline
    for n in range(1, TICKS + 1):
        rise = float((a[n:] - a[:-n]).max())
        assert rise <= CONFIG.max_step + CONFIG.ramp_per_tick * (n - 1) + 1e-12, (n, rise)


@PROPERTY
@given(
    st.lists(st.floats(0.0, 1.0, **finite), min_size=TICKS, max_size=TICKS),
    positions,
    velocities,
    tick_lengths,
    spool_speeds,
)
def test_a_motor_commanded_to_baseline_stays_at_baseline(
    m0: list[float],
    position: np.ndarray,
    velocity: np.ndarray,
    tick_s: np.ndarray,
    spool_speed: np.ndarray,
) -> None:
    # M1 and M2 held at baseline whatever M0 does and whatever the joints report: no rule raises a motor.
    command = np.column_stack([m0, np.full(TICKS, BASELINE_ACTIVATION), np.full(TICKS, BASELINE_ACTIVATION)])
    applied = play(command, position, velocity, tick_s, spool_speed)
    assert np.all(applied[:, 1:] == BASELINE_ACTIVATION)


@PROPERTY
@given(positions, velocities, tick_lengths, spool_speeds)
def test_a_command_the_rules_leave_alone_passes_bit_for_bit(
    position: np.ndarray,
    velocity: np.ndarray,
    tick_s: np.ndarray,
    spool_speed: np.ndarray,
) -> None:
    # Rises within the ramp's sustained slope, with the soft limits off, the slack rules out of reach (the
    # drawn spool speeds pay out loops) and the windings cool: the rules have nothing to do, so the
    # applied activation is the command itself, not a rounding of it.
    config = EnvelopeConfig(soft_limits=False, slack_guard_m=10.0, slack_trip_m=10.0)
    envelope = SafetyEnvelope(config)
    steps = np.arange(1, TICKS + 1) % 14  # rising for 13 ticks, then a fall to baseline
    command = BASELINE_ACTIVATION + config.ramp_per_tick * np.outer(steps, [1.0, 0.5, 0.25])
    t_s = 0.0
    for k in range(TICKS):
        action = envelope.limit(command[k], position[k], velocity[k])
        assert np.array_equal(action.applied, command[k]), k
        t_s += float(tick_s[k])
        observe(envelope, t_s, action.applied, position[k], velocity[k], spool_speed[k])
