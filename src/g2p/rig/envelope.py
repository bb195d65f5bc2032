"""The rig's safety envelope: what every rig's tick loop does to an activation before the motors get it.

Whatever the client (the learner, an RL agent, `ros2 topic pub`), each tick's activation passes through one
`SafetyEnvelope`, from what the rig knows at the tick's start (the previous tick's joint angles and
velocities, the activations applied so far), so that the simulator and the hardware driver apply the
same rules:

- **Soft joint limits** (ros2_control's joint_limits soft limits are the model): while a client drives
  the rig (a motor above baseline), a joint may move toward a stop at no more than
  `impact_speed_rad_s + k_position * (distance ahead - margin)`. Beyond that speed the tendons that drive
  it there are scaled down toward baseline, by `k_velocity` per rad/s of excess. Acting on measured speeds,
  one tick late and behind the motors' 30 ms lag, this holds the entries of G2P's own cycles but not an
  adversary's (docs/SIMULATOR.md, "The safety envelope").
- **A ramp** (the torque ramp of a motor driver, as ODrive's and VESC's), as a rate limit: over any n
  consecutive ticks a motor's applied activation rises by at most `max_step + ramp_per_tick * (n - 1)`,
  whatever the commands (a token bucket of `max_step`, refilled by `ramp_per_tick` a tick); falls pass
  at once. A stair step from baseline to 1 (babbling, a square wave) takes 12 ticks, and so does any
  sequence of smaller steps. Every tendon stepped at once (a square wave: one let go as two pull) throws
  the shank into its stop faster than a rule acting on measured speeds can brake it, one tick late and
  behind the motors' lag; the ramp spreads the step.
- **Slack loops**, estimated from the motors' current and power and the joints' velocities
  (g2p.rig.tendons): a motor whose tendon's loop is estimated beyond `slack_guard_m` is held at baseline
  until the tendon is taut again, so that its spool takes the slack up gently rather than snapping the
  tendon taut; a loop beyond `slack_trip_m` trips the rig, naming the tendon.
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
from dataclasses import asdict, dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from g2p.description.calibration_file import CalibrationError, read_parameters
from g2p.plant import Recording, TickSample, first_order_temperature
from g2p.rig.tendons import TENDON_ARMS_M, DriveRating, TendonEstimate
from g2p.safety import BASELINE_ACTIVATION, N_MOTORS
from g2p.validation import ConfigError, require

FloatArray = NDArray[np.float64]

# Which way each tendon turns each joint when it pulls (the paper's Fig 1d): +1 toward positive angles
# (counter-clockwise), -1 toward negative ones, 0 not at all. Rows M0, M1, M2; columns proximal, distal.
# M1 turns the hip ccw only; M0 the hip cw and the knee ccw; M2 both cw. A pulling tendon shortens, so it
# turns each joint against the sign of its length's coefficient.
TENDON_DIRECTIONS = -np.sign(TENDON_ARMS_M) + 0.0  # + 0.0: no -0.0
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


# The calibration's parameters (g2p.sim.calibration.PARAMETERS) the envelope takes, and where it puts each:
# (DriveRating or WindingRating, its field).
CALIBRATED_CONSTANTS: dict[str, tuple[tuple[str, str], ...]] = {
    "motor_kt_nm_per_a": (("drive", "kt_nm_per_a"),),
    "motor_resistance_ohm": (("drive", "resistance_ohm"), ("winding", "resistance_ohm")),
    "tendon_stiffness_n_per_m": (("drive", "tendon_stiffness_n_per_m"),),
    "motor_max_current_a": (("winding", "max_current_a"),),
    "winding_thermal_resistance_k_per_w": (("winding", "thermal_resistance_k_per_w"),),
    "winding_time_constant_s": (("winding", "time_constant_s"),),
}


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
        drive: the motors', spools' and tendons' rated constants (the tendon estimate's).
        max_step: the most a motor's activation rises in one tick, the ramp's bucket (dimensionless);
            1 = no ramp.
        ramp_per_tick: the sustained rise per tick, the bucket's refill (dimensionless; 0.06 at 78 Hz is
            4.7 /s).
        winding: the motors' rated thermal model.
        slack_trip_m: the cable estimated in a slack tendon's loop (g2p.rig.tendons) that trips the rig
            (m): a tendon leaves its channel at 60 mm, and a loop can grow by about 10 mm in a tick; the
            estimate errs 5-15 mm high, never low.
        slack_guard_m: the cable estimated in a slack tendon's loop from which its motor is held at baseline
            until the tendon is taut again (m): a spool reeling in slack at a high activation snaps the
            tendon taut (a snatch load); at baseline it takes the slack up gently. At most `slack_trip_m`
            (equal: no guard before the trip).
        calibration: the rig's calibration file (as `g2p-calibrate` writes it) or a packaged calibration's
            name, whose motor, tendon and winding constants (CALIBRATED_CONSTANTS) replace the rated ones
            of `drive` and `winding`; "" keeps the rated ones. The supply voltage is not among them: no
            rule uses it.
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
    drive: DriveRating = field(default_factory=DriveRating)
    slack_trip_m: float = 0.050
    slack_guard_m: float = 0.003
    calibration: str = ""
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
        require(self.slack_trip_m > 0, "slack_trip_m", f"must be > 0, got {self.slack_trip_m}")
        require(
            0 < self.slack_guard_m <= self.slack_trip_m,
            "slack_guard_m",
            f"must be in (0, slack_trip_m = {self.slack_trip_m}], got {self.slack_guard_m}",
        )
        for name in ("max_step", "ramp_per_tick"):
            value = getattr(self, name)
            require(0 < value <= 1, name, f"must be in (0, 1], got {value}")
        require(
            self.winding.ambient_c < self.derate_start_c < self.derate_full_c <= self.trip_c,
            "derate_start_c",
            f"need ambient < derate_start_c < derate_full_c <= trip_c, got {self.winding.ambient_c}, "
            f"{self.derate_start_c}, {self.derate_full_c}, {self.trip_c}",
        )
        if self.calibration:
            try:
                self.calibrated()
            except (CalibrationError, ConfigError) as err:
                raise ConfigError(f"calibration: {err}") from err

    def calibrated(self) -> EnvelopeConfig:
        """These rules with the calibration's constants in `drive` and `winding` (itself without one).

        Raises:
            g2p.description.calibration_file.CalibrationError: the file cannot be read.
            g2p.validation.ConfigError: a calibrated constant is invalid.
        """
        if not self.calibration:
            return self
        values = read_parameters(self.calibration)
        drive, winding = asdict(self.drive), asdict(self.winding)
        for name in CALIBRATED_CONSTANTS.keys() & values.keys():
            for part, field_name in CALIBRATED_CONSTANTS[name]:
                (drive if part == "drive" else winding)[field_name] = values[name]
        return replace(self, drive=DriveRating(**drive), winding=WindingRating(**winding), calibration="")


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
        tension_n: each tendon's estimated tension when the tick began (g2p.rig.tendons), shape (3,) (N).
        slack_loop_m: the cable estimated in each slack tendon's loop when the tick began, shape (3,) (m).
    """

    commanded: FloatArray
    applied: FloatArray
    joint_scale: FloatArray
    ramp_cap: FloatArray
    thermal_scale: FloatArray
    winding_c: FloatArray
    tension_n: FloatArray
    slack_loop_m: FloatArray

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
        config = config.calibrated()
        self.config = config
        """Its rules, with the calibration's constants (`EnvelopeConfig.calibrated`)."""
        self.baseline_activation = baseline_activation
        self.winding_c = np.full(N_MOTORS, config.winding.ambient_c)
        """Each winding's estimated temperature (deg C), shape (3,)."""
        stops = np.array([config.proximal_stops_rad, config.distal_stops_rad])  # (2, 2): joint, (low, up)
        self._lower, self._upper = stops[:, 0], stops[:, 1]
        self._last_t_s: float | None = None
        # The motors' activation over the last tick: a rig starts at baseline.
        self._last_activation = np.full(N_MOTORS, baseline_activation)
        # The ramp's bucket per motor: the most each may rise in the coming tick beyond its last activation.
        self._credit = np.full(N_MOTORS, config.max_step)
        self.tendons = TendonEstimate(config.drive)
        """Each tendon's length, tension and slack loop, from what the rig measures (g2p.rig.tendons)."""

    def limit(
        self, activation: FloatArray, position_rad: FloatArray | None, velocity_rad_s: FloatArray | None
    ) -> EnvelopeAction:
        """The activation to apply during the coming tick (the envelope's state changes in `observe`).

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
        ramp_cap = np.minimum(self._last_activation + self._credit, 1.0)
        applied = np.minimum(applied, ramp_cap)
        # A spool reeling in a slack loop is held at baseline (the snatch guard).
        applied = np.where(self.tendons.loop_m > cfg.slack_guard_m, base, applied)
        return EnvelopeAction(
            commanded=activation.copy(),
            applied=applied,
            joint_scale=joint_scale,
            ramp_cap=ramp_cap,
            thermal_scale=thermal_scale,
            winding_c=self.winding_c.copy(),
            tension_n=self.tendons.tension_n.copy(),
            slack_loop_m=self.tendons.loop_m.copy(),
        )

    @property
    def trip(self) -> str:
        """Why the envelope trips the rig ("" when it does not).

        A winding estimated at its cut-out, or a slack loop estimated beyond `slack_trip_m`.
        """
        cfg = self.config
        reasons = [
            f"M{i}'s winding estimated at {self.winding_c[i]:.1f} degC (cut-out {cfg.trip_c:g})"
            for i in np.flatnonzero(self.winding_c >= cfg.trip_c)
        ]
        loops = self.tendons.loop_m
        reasons += [
            f"tendon M{i}: an estimated {1000 * loops[i]:.0f} mm of cable paid into its slack loop "
            f"(trips at {1000 * cfg.slack_trip_m:g} mm, before it leaves its channel)"
            for i in np.flatnonzero(loops > cfg.slack_trip_m)
        ]
        return ", ".join(reasons)

    def observe(self, sample: TickSample, at_rest: bool = False) -> None:
        """Account for a tick the rig measured.

        Its end `t_s`, the activations applied over it (the ramp, the thermal estimate), the motors' current
        and power and the joints' velocities (the tendon estimate).

        Args:
            sample: the tick's sample.
            at_rest: the sample is a reset's (no tick behind it): the tendon estimate starts again there.

        The first observation (and one whose time goes back) only sets the clock.
        """
        last, self._last_t_s = self._last_t_s, sample.t_s
        activation = np.array(sample.activation, dtype=np.float64)
        # A rise spends the ramp's bucket, a fall refills it, and every tick adds ramp_per_tick, up to
        # max_step: then the rise over any n ticks is at most max_step + ramp_per_tick * (n - 1).
        cfg = self.config
        spent = activation - self._last_activation
        self._credit = np.clip(self._credit - spent + cfg.ramp_per_tick, 0.0, cfg.max_step)
        self._last_activation = activation
        if at_rest:
            self.tendons.reset()
        dt_s = 0.0 if last is None else sample.t_s - last
        if not at_rest and dt_s >= 0:  # the first observation starts the estimate
            self.tendons.update(dt_s, sample.current_a, sample.power_w, sample.velocity_rad_s)
        if dt_s <= 0:
            return
        w = self.config.winding
        current_a = activation * w.max_current_a
        self.winding_c = first_order_temperature(
            self.winding_c,
            current_a * current_a * w.resistance_ohm,
            dt_s,
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
            envelope.observe(ticks.sample(before))
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


def fastest_stop_entries(recording: Recording) -> FloatArray:
    """Each joint's fastest entry into its stops over a recording (`stop_entry_speeds`).

    Returns:
        (hip, knee), shape (2,) (rad/s; 0 for a joint that never entered a stop).
    """
    fastest = np.zeros(len(JOINT_STOPS_RAD))
    for j, stops in enumerate(JOINT_STOPS_RAD):
        entries = stop_entry_speeds(recording.position_rad[:, j], recording.velocity_rad_s[:, j], stops)
        fastest[j] = entries.max() if entries.size else 0.0
    return fastest
