"""The rig's safety envelope: what every rig's tick loop does to an activation before the motors get it.

Whatever the client (the learner, an RL agent, `ros2 topic pub`), each tick's activation passes through one
`SafetyEnvelope`, from what the rig knows at the tick's start (the previous tick's joint angles and
velocities, the activations applied so far), so that the simulator and the hardware driver apply the
same rules:

- **Soft joint limits** (ros2_control's joint_limits soft limits are the model): while a client drives
  the rig (a motor above baseline), a joint may move toward a stop at no more than
  `impact_speed_rad_s + k_position * (distance ahead - margin)`. Beyond that speed the tendons that drive
  it there are scaled down toward baseline, by `k_velocity` per rad/s of excess.
- **A ramp for steps** (the torque ramp of a motor driver, as ODrive's and VESC's): a motor's activation
  rises by at most `max_step` in one tick, and a motor still short of a larger step climbs on at
  `ramp_per_tick`; falls pass at once. A command that rises smoothly (G2P's limit cycles rise by about
  0.17 a tick at the 99th percentile) passes; a stair step from baseline to 1 (babbling, a square wave)
  takes 12 ticks. Every tendon stepped at once (a square wave: one let go as two pull) throws the shank
  into its stop faster than a rule acting on measured speeds can brake it, one tick late and behind the
  motors' lag; the ramp spreads the step.
- **A thermal budget per motor** (I^2 t, as motor drivers protect windings): each winding's temperature is
  estimated with the rated first-order thermal model from the current its current-mode driver regulates,
  the applied activation times the current at activation 1. The supply voltage only lowers the true
  current (back-EMF), so the estimate errs hot; and it is the same on every rig, whereas the Pi's current
  sensors sit on the drivers' supply side and read the supply current, not the winding's. From
  `derate_start_c` the motor's activation above baseline is scaled down, to baseline at `derate_full_c`,
  below the drivers' cut-out. The motor cools at baseline and comes back as it cools.

Each only lowers an activation above baseline. The envelope's state (the temperature estimates, the
last activation) lives across ticks and resets, as the windings' heat does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from g2p.plant import Recording, first_order_temperature
from g2p.safety import BASELINE_ACTIVATION, N_MOTORS
from g2p.validation import require

FloatArray = NDArray[np.float64]

# Which way each tendon turns each joint when it pulls (the paper's Fig 1d): +1 toward positive angles
# (counter-clockwise), -1 toward negative ones, 0 not at all. Rows M0, M1, M2; columns proximal, distal.
# M1 turns the hip ccw only; M0 the hip cw and the knee ccw; M2 both cw.
TENDON_DIRECTIONS = np.array([[-1.0, 1.0], [1.0, 0.0], [-1.0, -1.0]])
# The joints' stops (rad): the hip +-55 deg, the knee -100..0 deg (g2p/description/models/leg.xml; a test
# checks).
JOINT_STOPS_RAD = ((-math.radians(55.0), math.radians(55.0)), (-math.radians(100.0), 0.0))


@dataclass(frozen=True)
class WindingRating:
    """The rated thermal model of one motor's winding, as its datasheet gives it.

    Attributes:
        max_current_a: the winding current at activation 1, the drivers' limit (A).
        resistance_ohm: winding resistance (ohm).
        thermal_resistance_k_per_w: winding to ambient (K/W).
        time_constant_s: thermal time constant (s).
        ambient_c: ambient temperature, the estimate's start (deg C).
    """

    max_current_a: float = 8.0
    resistance_ohm: float = 0.6
    thermal_resistance_k_per_w: float = 2.0
    time_constant_s: float = 60.0
    ambient_c: float = 25.0


@dataclass(frozen=True)
class EnvelopeConfig:
    """The safety envelope's rules (module docstring).

    Attributes:
        proximal_stops_rad: the hip's (lower, upper) stops (rad).
        distal_stops_rad: the knee's (lower, upper) stops (rad).
        soft_limits: apply the soft joint limits.
        margin_rad: the soft limit's distance inside each stop (rad).
        impact_speed_rad_s: the speed toward a stop always allowed (rad/s).
        k_position: allowed speed toward a stop, beyond `impact_speed_rad_s`, per rad of distance
            beyond the margin (1/s).
        horizon_s: the distance is taken where the joint will be this much later at its speed (s): the
            tick's delay and the motors' lag.
        k_velocity: the excess's measure per rad/s above the allowed speed (s/rad); 1 = full.
        max_step: the most a motor's activation rises in one tick (dimensionless); 1 = no ramp.
        ramp_per_tick: the rise per tick of a motor still short of a step larger than `max_step`
            (dimensionless; 0.06 at 78 Hz is 4.7 /s).
        winding: the motors' rated thermal model.
        derate_start_c: estimated winding temperature from which a motor is derated (deg C).
        derate_full_c: estimated winding temperature at which a motor is held at baseline (deg C).
        trip_c: estimated winding temperature that trips the rig (deg C): the drivers' cut-out, which
            the derating keeps a motor from reaching.
    """

    proximal_stops_rad: tuple[float, float] = JOINT_STOPS_RAD[0]
    distal_stops_rad: tuple[float, float] = JOINT_STOPS_RAD[1]
    soft_limits: bool = True
    margin_rad: float = 0.05
    impact_speed_rad_s: float = 4.0
    k_position: float = 5.0
    horizon_s: float = 0.1
    k_velocity: float = 1.0
    max_step: float = 0.2
    ramp_per_tick: float = 0.06
    winding: WindingRating = field(default_factory=WindingRating)
    derate_start_c: float = 72.0
    derate_full_c: float = 78.0
    trip_c: float = 80.0

    def __post_init__(self) -> None:
        for name in ("proximal_stops_rad", "distal_stops_rad"):
            stops = getattr(self, name)
            require(len(stops) == 2 and stops[0] < stops[1], name, f"must be (lower, upper) rad, got {stops}")
        for name in (
            "margin_rad",
            "impact_speed_rad_s",
            "k_position",
            "horizon_s",
            "k_velocity",
        ):
            value = getattr(self, name)
            require(math.isfinite(value) and value >= 0, name, f"must be finite and >= 0, got {value}")
        for name in ("max_step", "ramp_per_tick"):
            value = getattr(self, name)
            require(0 < value <= 1, name, f"must be in (0, 1], got {value}")
        require(
            self.winding.ambient_c < self.derate_start_c < self.derate_full_c <= self.trip_c,
            "derate_start_c",
            f"need ambient < derate_start_c < derate_full_c <= trip_c, got {self.winding.ambient_c}, "
            f"{self.derate_start_c}, {self.derate_full_c}, {self.trip_c}",
        )


@dataclass(frozen=True)
class EnvelopeAction:
    """What the envelope did to one tick's activation.

    Attributes:
        commanded: the activation asked for, shape (3,).
        applied: the activation it let through, shape (3,).
        joint_scale: each motor's scale from the soft joint limits, shape (3,) (1 = untouched).
        ramp_cap: the highest activation the ramp let each motor reach: its last activation plus the rise
            allowed this tick, at most 1, shape (3,).
        thermal_scale: each motor's scale from its thermal budget, shape (3,) (1 = untouched).
        winding_c: each winding's estimated temperature when the tick began, shape (3,) (deg C).
    """

    commanded: FloatArray
    applied: FloatArray
    joint_scale: FloatArray
    ramp_cap: FloatArray
    thermal_scale: FloatArray
    winding_c: FloatArray

    @property
    def acted(self) -> bool:
        """Whether the envelope changed the activation."""
        return bool(np.any(self.applied != self.commanded))


class SafetyEnvelope:
    """The envelope of one rig: limits each tick's activation from the previous tick's measurements.

    Args:
        config: its rules.
        baseline_activation: the activation every motor keeps (dimensionless).
    """

    def __init__(
        self, config: EnvelopeConfig = EnvelopeConfig(), baseline_activation: float = BASELINE_ACTIVATION
    ) -> None:
        self.config = config
        self.baseline_activation = baseline_activation
        self.winding_c = np.full(N_MOTORS, config.winding.ambient_c)
        """Each winding's estimated temperature (deg C), shape (3,)."""
        stops = np.array([config.proximal_stops_rad, config.distal_stops_rad])  # (2, 2): joint, (low, up)
        self._lower, self._upper = stops[:, 0], stops[:, 1]
        self._last_t_s: float | None = None
        # The motors' activation over the last tick: a rig starts at baseline.
        self._last_activation = np.full(N_MOTORS, baseline_activation)
        self._short = np.zeros(N_MOTORS, dtype=bool)  # motors the ramp held below their last command

    def limit(
        self, activation: FloatArray, position_rad: FloatArray | None, velocity_rad_s: FloatArray | None
    ) -> EnvelopeAction:
        """The activation to apply during the coming tick; call it once a tick (the ramp keeps count).

        Args:
            activation: the activation decided (3,); clipped to [baseline, 1] first, as the plant would.
            position_rad: joint angles at the end of the previous tick (2,); None when unknown.
            velocity_rad_s: joint velocities at the end of the previous tick (2,); None when unknown.
        """
        cfg = self.config
        base = self.baseline_activation
        # What the rig would apply without the envelope (a tracker's output may leave [baseline, 1]).
        activation = np.clip(activation, base, 1.0)
        joint_scale = np.ones(N_MOTORS)
        # Only while a client drives the rig (a motor above baseline): the rig's own baseline (idle, after
        # a cancel, a fault or a stop) stays baseline.
        driven = bool(np.any(activation > base))
        if cfg.soft_limits and driven and position_rad is not None and velocity_rad_s is not None:
            for side, distance, toward in (
                (1.0, self._upper - position_rad, velocity_rad_s),
                (-1.0, position_rad - self._lower, -velocity_rad_s),
            ):
                ahead = distance - cfg.horizon_s * np.maximum(toward, 0.0)
                allowed = cfg.impact_speed_rad_s + cfg.k_position * np.maximum(ahead - cfg.margin_rad, 0.0)
                excess = np.clip((toward - allowed) * cfg.k_velocity, 0.0, 1.0)  # (2,) per joint
                drives = TENDON_DIRECTIONS * side  # (3, 2): +1 for a tendon that turns the joint that way
                for j in np.flatnonzero(excess):
                    joint_scale = np.minimum(joint_scale, np.where(drives[:, j] > 0, 1.0 - excess[j], 1.0))
        span = cfg.derate_full_c - cfg.derate_start_c
        thermal_scale = np.clip((cfg.derate_full_c - self.winding_c) / span, 0.0, 1.0)
        scale = joint_scale * thermal_scale
        # Untouched motors keep their activation bit for bit: (a - base) + base need not equal a.
        applied = np.where(scale < 1.0, base + (activation - base) * scale, activation)
        rise = np.where(self._short, min(cfg.ramp_per_tick, cfg.max_step), cfg.max_step)
        ramp_cap = np.minimum(self._last_activation + rise, 1.0)
        self._short = applied > ramp_cap
        applied = np.minimum(applied, ramp_cap)
        return EnvelopeAction(
            commanded=activation.copy(),
            applied=applied,
            joint_scale=joint_scale,
            ramp_cap=ramp_cap,
            thermal_scale=thermal_scale,
            winding_c=self.winding_c.copy(),
        )

    @property
    def trip(self) -> str:
        """Why the envelope trips the rig ("" when it does not): a winding estimated at its cut-out."""
        hot = np.flatnonzero(self.winding_c >= self.config.trip_c)
        if not hot.size:
            return ""
        return ", ".join(
            f"M{i}'s winding estimated at {self.winding_c[i]:.1f} degC (cut-out {self.config.trip_c:g})"
            for i in hot
        )

    def observe(self, t_s: float, activation: FloatArray) -> None:
        """Account for a tick that ended at `t_s` (s, plant clock), its motors at `activation` (3,).

        The first observation (and one whose time goes back) only sets the clock.
        """
        last, self._last_t_s = self._last_t_s, t_s
        self._last_activation = np.array(activation, dtype=np.float64)
        if last is None or t_s <= last:
            return
        w = self.config.winding
        current_a = activation * w.max_current_a
        self.winding_c = first_order_temperature(
            self.winding_c,
            current_a * current_a * w.resistance_ohm,
            t_s - last,
            w.thermal_resistance_k_per_w,
            w.time_constant_s,
            w.ambient_c,
        )


def replay(decided: FloatArray, ticks: Recording, config: EnvelopeConfig = EnvelopeConfig()) -> FloatArray:
    """What a rig's envelope applied to the `decided` activations, from the ticks the rig returned.

    Each tick's activation is limited from the tick before it, as the rig's loop limits it; the windings'
    estimates start at ambient.

    Args:
        decided: the activations decided (by the client, through the rig's gate), shape (N, 3).
        ticks: the N ticks played, or N + 1 with the tick before the first in front (without it the first
            is limited with no measurement, as from rest).
        config: the rig's envelope.

    Returns:
        The applied activations, shape (N, 3).
    """
    decided = np.asarray(decided, dtype=np.float64)
    lead = len(ticks) - len(decided)
    require(lead in (0, 1), "ticks", f"need {len(decided)} or {len(decided) + 1} ticks, got {len(ticks)}")
    envelope = SafetyEnvelope(config)
    applied = np.empty_like(decided)
    for k, activation in enumerate(decided):
        before = k + lead - 1  # the tick the rig had when it decided tick k
        if before >= 0:
            envelope.observe(float(ticks.t_s[before]), ticks.activation[before])
            applied[k] = envelope.limit(
                activation, ticks.position_rad[before], ticks.velocity_rad_s[before]
            ).applied
        else:
            applied[k] = envelope.limit(activation, None, None).applied
    return applied


def stop_entry_speeds(
    position_rad: FloatArray,
    velocity_rad_s: FloatArray,
    stops_rad: tuple[float, float],
    within_rad: float = 0.02,
) -> FloatArray:
    """The speeds at which a joint entered its stops, from its ticks: how hard it struck them.

    A tick enters a stop when the joint is within `within_rad` of it and was not the tick before; its
    speed is that tick's measured |velocity|.

    Args:
        position_rad: the joint's angle per tick, shape (N,) (rad).
        velocity_rad_s: its velocity per tick, shape (N,) (rad/s).
        stops_rad: its (lower, upper) stops (rad).
        within_rad: how near a stop counts as at it (rad).

    Returns:
        One speed per entry, in order, shape (M,) (rad/s).
    """
    low, high = stops_rad
    at = (position_rad <= low + within_rad) | (position_rad >= high - within_rad)
    entered = np.flatnonzero(at[1:] & ~at[:-1]) + 1
    speeds: FloatArray = np.abs(velocity_rad_s[entered])
    return speeds
