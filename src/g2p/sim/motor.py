"""The electrical model of the rig's brushless motors: current, torque, tension and power.

Activation is the fraction of the maximal motor current. The driver's current loop and the command path
make the current follow the activation with a first-order lag (modelled by the MuJoCo actuator's filter
dynamics). The motor torque is Kt * I on a spool of radius r, so the tendon is pulled with Kt * I / r.
The electrical power drawn is the copper loss plus the mechanical power, P = I^2 R + Kt I w, with w the
spool speed in the reel-in direction: P is negative when a tendon backdrives its motor fast enough to
regenerate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class MotorConstants:
    """Electrical and mechanical constants shared by the three motors.

    Attributes:
        kt_nm_per_a: torque constant (N m / A), equal to the back-EMF constant (V s / rad) in SI units.
        resistance_ohm: winding resistance (ohm).
        max_current_a: current at activation 1 (A).
        spool_radius_m: radius of the spool the tendon winds on (m).
    """

    kt_nm_per_a: float
    resistance_ohm: float
    max_current_a: float
    spool_radius_m: float

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{f.name}: must be a finite number > 0, got {value!r}")

    @property
    def max_torque_nm(self) -> float:
        """Motor torque at activation 1 (N m)."""
        return self.kt_nm_per_a * self.max_current_a

    @property
    def max_tension_n(self) -> float:
        """Static tendon tension at activation 1 (N)."""
        return self.max_torque_nm / self.spool_radius_m


def electrical_power_w(
    current_a: FloatArray, spool_speed_rad_s: FloatArray, motor: MotorConstants
) -> FloatArray:
    """Electrical power drawn by motors, P = I^2 R + Kt I w.

    Args:
        current_a: motor currents, any shape (A).
        spool_speed_rad_s: spool speeds in the reel-in direction, same shape (rad/s).
        motor: the motor constants.

    Returns:
        Power per motor, same shape (W); negative when the motor regenerates.
    """
    return current_a * (current_a * motor.resistance_ohm + motor.kt_nm_per_a * spool_speed_rad_s)
