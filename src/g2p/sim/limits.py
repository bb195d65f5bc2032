"""The simulated rig's physical limits: supply voltage, winding heat, tendon strength, tendon derailment.

An ideal current source would let a client spin a spool at any speed, heat a winding without end and
stretch a tendon to any tension. The rig's hardware does not: these are what it has, as the simulator
models them (`MujocoLeg.step`; docs/SIMULATOR.md, "The rig's limits", gives the reason for each value):

- the drivers' current limit is the current at activation 1 (`MotorConstants.max_current_a`), and the
  supply voltage caps the current further once the spool turns: I <= (V - Kt w) / R, so the current falls
  as a spool reels in faster, to 0 at the no-load speed V / Kt;
- each winding heats from its copper loss I^2 R through a first-order thermal model (a thermal resistance
  to ambient and a time constant); at the cut-out temperature its driver switches the motor off;
- a tendon pulled beyond its breaking tension snaps;
- a slack tendon into which its spool pays out more than `tendon_derail_payout_m` of cable leaves its
  channel (the paper saw slack tendons come off their channels, and added flanges and baseline tension).

A cut-out, a snapped tendon and a derailment trip the rig: `MujocoLeg.fault` says which, the tick loop
raises `g2p.rig.tick_loop.RigTripped`, and the motor is off or the tendon carries no force until an
operator resets the rig (`MujocoLeg.reset`), and the winding has cooled.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import mujoco
import numpy as np
from numpy.typing import NDArray

from g2p.plant import first_order_temperature
from g2p.sim.model import ModelError, require_numerics
from g2p.sim.motor import MotorConstants

FloatArray = NDArray[np.float64]

# The model's custom numerics holding each limit (leg.xml), by PhysicalLimits field.
NUMERICS = {
    "supply_voltage_v": "supply_voltage",
    "winding_thermal_resistance_k_per_w": "winding_thermal_resistance",
    "winding_time_constant_s": "winding_time_constant",
    "ambient_c": "ambient_temperature",
    "winding_cutout_c": "winding_cutout_temperature",
    "tendon_rated_n": "tendon_rated_tension",
    "tendon_breaking_n": "tendon_breaking_tension",
    "tendon_derail_payout_m": "tendon_derail_payout",
}
# A winding that cut out switches back on (at the next reset) once this much below its cut-out (K).
COOLDOWN_HYSTERESIS_K = 10.0


@dataclass(frozen=True)
class PhysicalLimits:
    """The rig's physical limits (see the module docstring).

    Attributes:
        supply_voltage_v: the motor drivers' supply voltage (V).
        winding_thermal_resistance_k_per_w: each winding's thermal resistance to ambient (K/W).
        winding_time_constant_s: each winding's thermal time constant (s).
        ambient_c: ambient temperature, and the windings' at start (deg C).
        winding_cutout_c: the temperature at which a driver switches its motor off (deg C).
        tendon_rated_n: each tendon's working load (N); beyond it, ticks count as overloaded.
        tendon_breaking_n: the tension at which a tendon snaps (N).
        tendon_derail_payout_m: the cable a spool may pay out into its slack tendon before the tendon
            leaves its channel (m); a taut tendon takes the loop back up.
    """

    supply_voltage_v: float
    winding_thermal_resistance_k_per_w: float
    winding_time_constant_s: float
    ambient_c: float
    winding_cutout_c: float
    tendon_rated_n: float
    tendon_breaking_n: float
    tendon_derail_payout_m: float

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (math.isfinite(value) and (value > 0 or f.name == "ambient_c")):
                raise ValueError(f"{f.name}: must be a finite number > 0, got {value!r}")
        if not self.ambient_c < self.winding_cutout_c:
            raise ValueError(
                f"winding_cutout_c: must be above ambient_c ({self.ambient_c}), got {self.winding_cutout_c}"
            )
        if not self.tendon_rated_n <= self.tendon_breaking_n:
            raise ValueError(
                f"tendon_breaking_n: must be at least tendon_rated_n ({self.tendon_rated_n}), "
                f"got {self.tendon_breaking_n}"
            )

    @classmethod
    def from_model(cls, model: mujoco.MjModel) -> PhysicalLimits:
        """The limits a compiled model holds in its custom numerics.

        Raises:
            ModelError: the model lacks some (the message names every one, with the packaged values), or
                a value is not physical.
        """
        require_numerics(model, NUMERICS.values())
        values = {}
        for field, name in NUMERICS.items():
            nid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, name)
            values[field] = float(model.numeric_data[model.numeric_adr[nid]])
        try:
            return cls(**values)
        except ValueError as err:
            raise ModelError(f"invalid rig limits in the model: {err}") from err


def available_current_a(
    commanded_a: FloatArray, spool_speed_rad_s: FloatArray, motor: MotorConstants, supply_v: float
) -> FloatArray:
    """The current a driver can put through a winding: the command, capped by the supply voltage.

    Args:
        commanded_a: the currents commanded, any shape (A, >= 0).
        spool_speed_rad_s: the spools' speeds in the reel-in direction, same shape (rad/s).
        motor: the motor constants (Kt = the back-EMF constant, R).
        supply_v: the supply voltage (V).

    Returns:
        min(command, (V - Kt w) / R), never below 0, same shape (A): a spool reeling in at its no-load
        speed V / Kt gets no current; one paying out (w < 0) gets its command.
    """
    headroom = (supply_v - motor.kt_nm_per_a * spool_speed_rad_s) / motor.resistance_ohm
    return np.clip(headroom, 0.0, commanded_a)


def winding_temperature_c(
    temperature_c: FloatArray, copper_loss_w: FloatArray, dt_s: float, limits: PhysicalLimits
) -> FloatArray:
    """The windings' temperatures (3,) (deg C) after `dt_s` of a constant copper loss (3,) (W)."""
    return first_order_temperature(
        temperature_c,
        copper_loss_w,
        dt_s,
        limits.winding_thermal_resistance_k_per_w,
        limits.winding_time_constant_s,
        limits.ambient_c,
    )
