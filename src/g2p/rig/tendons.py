"""The tendons seen from what every rig measures: spool speeds, tendon stretch and tension, slack loops.

No rig measures a spool's angle or a tendon's tension, and the simulator's readings of them (its sub-step
tension peaks, the cable paid into a slack tendon) do not exist on the hardware. What every rig does
measure each tick (the INA219s on the Pi, the simulated sensors) is enough:

- **Spool speed** from each motor's electrical power: P = I^2 R + Kt I w (g2p.sim.motor), so
  w = (P - I^2 R) / (Kt I), in the reel-in direction (rad/s), from the tick's mean current and power
  (the relation the calibration fits). At baseline a motor still carries 1.2 A, so w is always defined.
- **Tendon length** L = arms . q + r theta (leg.xml's fixed tendons): its rate is the joints' velocities
  through the moment arms plus the spool's speed times its radius. Integrated, L drifts with the
  errors of w; a stretched tendon pulls its spool with Kt I / r at equilibrium, so L is drawn toward that
  stretch, I Kt / (r k), by `anchor_per_tick` each tick (a complementary filter: the integral for what
  is fast, the current for what is slow).
- **Tension** k max(L, 0), and the **slack loop**: while L < 0, the cable the spool pays out (-r w, net
  of what it reels back in), which is what derails a tendon (g2p.sim.limits).

Checked against the simulated leg's own readings (tests/rig/test_tendons.py; docs/SIMULATOR.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from g2p.safety import N_MOTORS
from g2p.validation import require

FloatArray = NDArray[np.float64]

# Each tendon's length per joint angle (m/rad), rows M0, M1, M2, columns proximal, distal: leg.xml's fixed
# tendons' coefficients (a test checks); a tendon lengthens as a joint turns away from the way it pulls.
TENDON_ARMS_M = np.array([[0.025, -0.025], [-0.05, 0.0], [0.025, 0.015]])


@dataclass(frozen=True)
class DriveRating:
    """The rated constants of the motors, spools and tendons (leg.xml's; a test checks).

    Attributes:
        kt_nm_per_a: torque constant (N m / A).
        resistance_ohm: winding resistance (ohm).
        spool_radius_m: spool radius (m).
        tendon_stiffness_n_per_m: each tendon's series stiffness (N/m).
        anchor_per_tick: how far each tick draws the estimated length toward the stretch the current holds
            (dimensionless, above 0 and at most 1).
    """

    kt_nm_per_a: float = 0.075
    resistance_ohm: float = 0.6
    spool_radius_m: float = 0.01
    tendon_stiffness_n_per_m: float = 4000.0
    anchor_per_tick: float = 0.05

    def __post_init__(self) -> None:
        for name in ("kt_nm_per_a", "resistance_ohm", "spool_radius_m", "tendon_stiffness_n_per_m"):
            value = getattr(self, name)
            require(value > 0 and np.isfinite(value), name, f"must be finite and > 0, got {value}")
        require(
            0 < self.anchor_per_tick <= 1, "anchor_per_tick", f"must be in (0, 1], got {self.anchor_per_tick}"
        )


def spool_speed_rad_s(current_a: FloatArray, power_w: FloatArray, rating: DriveRating) -> FloatArray:
    """Each spool's speed in the reel-in direction from its motor's current and power, any shape (rad/s).

    0 where the current is 0 (a motor cut out, or off): its speed is not observable.
    """
    current_a = np.asarray(current_a, dtype=np.float64)
    safe = np.where(current_a > 0.0, current_a, 1.0)
    speed = (power_w - current_a * current_a * rating.resistance_ohm) / (rating.kt_nm_per_a * safe)
    result: FloatArray = np.where(current_a > 0.0, speed, 0.0)
    return result


class TendonEstimate:
    """Each tendon's length, tension and slack loop, estimated tick by tick (module docstring).

    Args:
        rating: the rated constants.
    """

    def __init__(self, rating: DriveRating = DriveRating()) -> None:
        self.rating = rating
        self.length_m = np.zeros(N_MOTORS)
        """Each tendon's estimated stretch (> 0) or slack (< 0) (m), shape (3,)."""
        self.loop_m = np.zeros(N_MOTORS)
        """The cable each spool has paid into its slack tendon (m), shape (3,)."""
        self.spool_speed_rad_s = np.zeros(N_MOTORS)
        """Each spool's speed over the last tick, reel-in positive (rad/s), shape (3,)."""
        self._started = False

    @property
    def tension_n(self) -> FloatArray:
        """Each tendon's estimated tension (N), shape (3,)."""
        result: FloatArray = self.rating.tendon_stiffness_n_per_m * np.maximum(self.length_m, 0.0)
        return result

    def _held_stretch_m(self, current_a: FloatArray) -> FloatArray:
        """The stretch at which each tendon balances its motor's torque (m), shape (3,)."""
        r = self.rating
        result: FloatArray = current_a * r.kt_nm_per_a / (r.spool_radius_m * r.tendon_stiffness_n_per_m)
        return result

    def update(
        self, dt_s: float, current_a: FloatArray, power_w: FloatArray, velocity_rad_s: FloatArray
    ) -> None:
        """Account for one tick of `dt_s` (s).

        Args:
            dt_s: the tick's length (s).
            current_a: the motors' mean currents over it, shape (3,) (A).
            power_w: their mean electrical power, shape (3,) (W).
            velocity_rad_s: the joints' velocities over it, shape (2,) (rad/s).

        The first call starts the estimate at equilibrium: each tendon stretched as its current holds it.
        """
        r = self.rating
        current_a = np.asarray(current_a, dtype=np.float64)
        held = self._held_stretch_m(current_a)
        if not self._started:
            self.length_m, self._started = held, True
            return
        w = spool_speed_rad_s(current_a, power_w, r)
        self.spool_speed_rad_s = w
        rate = TENDON_ARMS_M @ np.asarray(velocity_rad_s, dtype=np.float64) + r.spool_radius_m * w
        length = self.length_m + rate * dt_s
        self.length_m = length + r.anchor_per_tick * (held - length)
        paid = -r.spool_radius_m * w * dt_s
        self.loop_m = np.where(self.length_m < 0.0, np.maximum(self.loop_m + paid, 0.0), 0.0)

    def reset(self) -> None:
        """Forget the estimate (a rig put back at rest): the next update starts it at equilibrium."""
        self.length_m = np.zeros(N_MOTORS)
        self.loop_m = np.zeros(N_MOTORS)
        self.spool_speed_rad_s = np.zeros(N_MOTORS)
        self._started = False
