"""A calibration of the simulated rig: named physical parameters of the leg, written into its MuJoCo model.

A calibration file is a small versioned YAML document (docs/SIMULATOR.md, "Calibration"; its format is
read in g2p.description.calibration_file, which needs no MuJoCo):

    format: g2p-leg-calibration
    version: 1
    model: g2p_leg                 # the MJCF model's name: the leg layout it calibrates
    parameters:                    # any subset of PARAMETERS; the others keep the model's values
      belt_drag_n: 3.2
      proximal_encoder_offset_rad: 0.012
    intervals: {...}               # optional: 95 % half-widths of the estimates (written by g2p-calibrate)
    undetermined: [...]            # optional: parameters the data did not determine
    fit: {...}                     # optional: where the values came from (bag, errors)

Most parameters are the MJCF model's (joint losses, tendon stiffness and moment arms, motor lag and current,
belt and foot); three are the sensors' (the two encoder zero offsets and the encoder delay), which the plant
applies to what it reads. `MujocoLegConfig.calibration` names a file, or one of the calibrations packaged in
g2p/description/models/calibrations/ by its name (e.g. "paper").
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np
import yaml

from g2p.description.calibration_file import (
    FORMAT,
    MODEL_NAME,
    VERSION,
    CalibrationError,
    check_document,
    packaged_calibrations,
    read_document,
    resolve_calibration_path,
)
from g2p.plant import MOTOR_NAMES, FloatArray

# The encoder delay the plant can apply (s): its history of sub-step angles covers this much.
MAX_ENCODER_DELAY_S = 0.05


@dataclass(frozen=True)
class LegParameter:
    """One physical parameter a calibration can set.

    Attributes:
        name: its name in calibration files, with its unit.
        doc: what it is.
        low: the smallest physical value accepted (and the fit's lower bound).
        high: the largest physical value accepted (and the fit's upper bound).
        read: its value in a compiled model (None for the sensors' parameters, which are 0 by default).
        write: sets it in a compiled model (None for the sensors' parameters). Every parameter is a
            run-time field of mjModel, so writing it after compiling equals compiling it in.
    """

    name: str
    doc: str
    low: float
    high: float
    read: Callable[[mujoco.MjModel], float] | None = None
    write: Callable[[mujoco.MjModel, float], None] | None = None

    @property
    def is_sensor(self) -> bool:
        """Whether the plant applies it to its readings rather than to the physics."""
        return self.write is None


def _id(model: mujoco.MjModel, kind: mujoco.mjtObj, name: str) -> int:
    found = int(mujoco.mj_name2id(model, kind, name))
    if found < 0:
        raise CalibrationError(f"the model has no {kind.name.removeprefix('mjOBJ_').lower()} named {name!r}")
    return found


def _field(
    attr: str, index: Callable[[mujoco.MjModel], tuple[Any, ...]]
) -> tuple[Callable[[mujoco.MjModel], float], Callable[[mujoco.MjModel, float], None]]:
    """Read and write a run-time field of the compiled model at the places `index` finds (all set alike)."""

    def read(model: mujoco.MjModel) -> float:
        return float(np.ravel(getattr(model, attr)[index(model)])[0])

    def write(model: mujoco.MjModel, value: float) -> None:
        getattr(model, attr)[index(model)] = value

    return read, write


def _dof(joint: str) -> Callable[[mujoco.MjModel], tuple[Any, ...]]:
    return lambda m: (int(m.jnt_dofadr[_id(m, mujoco.mjtObj.mjOBJ_JOINT, joint)]),)


def _jnt(joint: str) -> Callable[[mujoco.MjModel], tuple[Any, ...]]:
    return lambda m: (_id(m, mujoco.mjtObj.mjOBJ_JOINT, joint),)


def _wrap(tendon: str, joint: str) -> Callable[[mujoco.MjModel], tuple[Any, ...]]:
    """The tendon's wrap entry on `joint`: its coefficient is the signed moment arm (m)."""

    def index(m: mujoco.MjModel) -> tuple[Any, ...]:
        tid = _id(m, mujoco.mjtObj.mjOBJ_TENDON, tendon)
        jid = _id(m, mujoco.mjtObj.mjOBJ_JOINT, joint)
        adr, num = int(m.tendon_adr[tid]), int(m.tendon_num[tid])
        for w in range(adr, adr + num):
            if int(m.wrap_objid[w]) == jid and int(m.wrap_type[w]) == int(mujoco.mjtWrap.mjWRAP_JOINT):
                return (w,)
        raise CalibrationError(f"tendon {tendon!r} does not cross joint {joint!r}")

    return index


def _motors(kind: mujoco.mjtObj, *columns: int) -> Callable[[mujoco.MjModel], tuple[Any, ...]]:
    def index(m: mujoco.MjModel) -> tuple[Any, ...]:
        ids = [_id(m, kind, name) for name in MOTOR_NAMES]
        return (ids, *columns)

    return index


def _gain_factor(
    numeric_name: str,
) -> tuple[Callable[[mujoco.MjModel], float], Callable[[mujoco.MjModel, float], None]]:
    """A factor of the actuators' gain Kt * I_max (`motor_kt` or `motor_max_current`); the gain follows."""

    def numeric(m: mujoco.MjModel, name: str) -> int:
        return int(m.numeric_adr[_id(m, mujoco.mjtObj.mjOBJ_NUMERIC, name)])

    def read(m: mujoco.MjModel) -> float:
        return float(m.numeric_data[numeric(m, numeric_name)])

    def write(m: mujoco.MjModel, value: float) -> None:
        m.numeric_data[numeric(m, numeric_name)] = value
        m.actuator_gainprm[_motors(mujoco.mjtObj.mjOBJ_ACTUATOR, 0)(m)] = (
            m.numeric_data[numeric(m, "motor_kt")] * m.numeric_data[numeric(m, "motor_max_current")]
        )

    return read, write


def _numeric(name: str) -> tuple[Callable[[mujoco.MjModel], float], Callable[[mujoco.MjModel, float], None]]:
    """A custom numeric of the model (the rig's limits, g2p.sim.limits)."""
    return _field("numeric_data", lambda m: (int(m.numeric_adr[_id(m, mujoco.mjtObj.mjOBJ_NUMERIC, name)]),))


_ACTUATORS = mujoco.mjtObj.mjOBJ_ACTUATOR
_TENDONS = mujoco.mjtObj.mjOBJ_TENDON


def _parameters() -> tuple[LegParameter, ...]:
    def p(
        name: str, doc: str, low: float, high: float, rw: tuple[Callable[..., Any], ...] = ()
    ) -> LegParameter:
        read, write = rw if rw else (None, None)
        return LegParameter(name, doc, low, high, read, write)

    return (
        p(
            "proximal_damping_nms",
            "hip viscous damping (N m s/rad)",
            0.0,
            1.0,
            _field("dof_damping", _dof("proximal")),
        ),
        p(
            "distal_damping_nms",
            "knee viscous damping (N m s/rad)",
            0.0,
            1.0,
            _field("dof_damping", _dof("distal")),
        ),
        p(
            "proximal_friction_nm",
            "hip Coulomb friction (N m)",
            0.0,
            1.0,
            _field("dof_frictionloss", _dof("proximal")),
        ),
        p(
            "distal_friction_nm",
            "knee Coulomb friction (N m)",
            0.0,
            1.0,
            _field("dof_frictionloss", _dof("distal")),
        ),
        p(
            "tendon_stiffness_n_per_m",
            "series stiffness of each tendon (N/m)",
            500.0,
            40000.0,
            _field("tendon_stiffness", lambda m: ([_id(m, _TENDONS, n) for n in MOTOR_NAMES],)),
        ),
        p(
            "m0_proximal_arm_m",
            "M0's signed moment arm on the hip (m; + pulls clockwise)",
            0.005,
            0.1,
            _field("wrap_prm", _wrap("M0", "proximal")),
        ),
        p(
            "m0_distal_arm_m",
            "M0's signed moment arm on the knee (m)",
            -0.1,
            -0.005,
            _field("wrap_prm", _wrap("M0", "distal")),
        ),
        p(
            "m1_proximal_arm_m",
            "M1's signed moment arm on the hip (m)",
            -0.15,
            -0.005,
            _field("wrap_prm", _wrap("M1", "proximal")),
        ),
        p(
            "m2_proximal_arm_m",
            "M2's signed moment arm on the hip (m)",
            0.005,
            0.1,
            _field("wrap_prm", _wrap("M2", "proximal")),
        ),
        p(
            "m2_distal_arm_m",
            "M2's signed moment arm on the knee (m)",
            0.003,
            0.1,
            _field("wrap_prm", _wrap("M2", "distal")),
        ),
        p(
            "motor_lag_s",
            "first-order lag of the motor current (s)",
            0.002,
            0.2,
            _field("actuator_dynprm", _motors(_ACTUATORS, 0)),
        ),
        p(
            "motor_max_current_a",
            "motor current at activation 1 (A): the motors' gain",
            1.0,
            30.0,
            _gain_factor("motor_max_current"),
        ),
        p(
            "motor_kt_nm_per_a",
            "the motors' torque constant (N m/A), equal to their back-EMF constant (V s/rad)",
            0.005,
            1.0,
            _gain_factor("motor_kt"),
        ),
        p(
            "motor_resistance_ohm",
            "each winding's resistance (ohm)",
            0.01,
            20.0,
            _numeric("motor_resistance"),
        ),
        p(
            "belt_drag_n",
            "Coulomb drag of the belt (N)",
            0.0,
            200.0,
            _field("dof_frictionloss", _dof("belt")),
        ),
        p(
            "belt_damping_ns_per_m",
            "viscous drag of the belt (N s/m)",
            0.0,
            500.0,
            _field("dof_damping", _dof("belt")),
        ),
        p(
            "belt_span_stiffness_n_per_m",
            "vertical stiffness of the belt span under the foot (N/m)",
            100.0,
            20000.0,
            _field("jnt_stiffness", _jnt("belt_sag")),
        ),
        p(
            "belt_span_damping_ns_per_m",
            "vertical damping of the belt span (N s/m)",
            0.5,
            200.0,
            _field("dof_damping", _dof("belt_sag")),
        ),
        p(
            "foot_friction",
            "sliding friction coefficient of the foot pad on the belt",
            0.05,
            3.0,
            _field("pair_friction", lambda m: (0, [0, 1])),
        ),
        p(
            "supply_voltage_v",
            "the motor drivers' supply voltage (V)",
            3.0,
            60.0,
            _numeric("supply_voltage"),
        ),
        p(
            "winding_thermal_resistance_k_per_w",
            "each winding's thermal resistance to ambient (K/W)",
            0.1,
            50.0,
            _numeric("winding_thermal_resistance"),
        ),
        p(
            "winding_time_constant_s",
            "each winding's thermal time constant (s)",
            1.0,
            3600.0,
            _numeric("winding_time_constant"),
        ),
        p(
            "winding_cutout_c",
            "the drivers' thermal cut-out (deg C)",
            40.0,
            200.0,
            _numeric("winding_cutout_temperature"),
        ),
        p(
            "tendon_rated_tension_n",
            "each tendon's working load (N)",
            1.0,
            1000.0,
            _numeric("tendon_rated_tension"),
        ),
        p(
            "tendon_breaking_tension_n",
            "the tension at which a tendon snaps (N)",
            1.0,
            2000.0,
            _numeric("tendon_breaking_tension"),
        ),
        p(
            "tendon_derail_payout_m",
            "cable a spool may pay out into its slack tendon before it derails (m)",
            0.001,
            0.5,
            _numeric("tendon_derail_payout"),
        ),
        p(
            "proximal_encoder_offset_rad",
            "hip encoder zero offset: reading minus true angle (rad)",
            -0.3,
            0.3,
        ),
        p("distal_encoder_offset_rad", "knee encoder zero offset: reading minus true angle (rad)", -0.3, 0.3),
        p("encoder_delay_s", "age of the joint angles a tick reports (s)", 0.0, MAX_ENCODER_DELAY_S),
    )


PARAMETERS: dict[str, LegParameter] = {p.name: p for p in _parameters()}


@dataclass(frozen=True)
class LegCalibration:
    """Values for some of PARAMETERS, and what the fit that produced them said.

    Attributes:
        parameters: physical values by parameter name (units in the names).
        intervals: 95 % confidence half-widths by parameter name (inf when the data do not determine it).
        undetermined: names of the parameters the data did not determine (their values are the priors').
        fit: free-form record of the fit (bag, errors before and after, held-out error).
        source: the file it was read from ("" when built in memory).
    """

    parameters: Mapping[str, float]
    intervals: Mapping[str, float] = field(default_factory=dict)
    undetermined: tuple[str, ...] = ()
    fit: Mapping[str, Any] = field(default_factory=dict)
    source: str = ""

    def __post_init__(self) -> None:
        where = self.source or "calibration"
        for name, value in self.parameters.items():
            spec = PARAMETERS.get(name)
            if spec is None:
                raise CalibrationError(
                    f"{where}: unknown parameter {name!r} (known: {', '.join(PARAMETERS)})"
                )
            if not (
                isinstance(value, int | float) and math.isfinite(value) and spec.low <= value <= spec.high
            ):
                raise CalibrationError(
                    f"{where}: {name} must be a number in [{spec.low}, {spec.high}], got {value!r}"
                )

    def value(self, name: str, default: float = 0.0) -> float:
        """The calibrated value of `name`, or `default` when this calibration does not set it."""
        return float(self.parameters.get(name, default))

    @property
    def encoder_offset_rad(self) -> FloatArray:
        """Zero offsets of the (proximal, distal) encoders, shape (2,) (rad)."""
        return np.array(
            [self.value("proximal_encoder_offset_rad"), self.value("distal_encoder_offset_rad")],
            dtype=np.float64,
        )

    @property
    def encoder_delay_s(self) -> float:
        """Age of the joint angles a tick reports (s)."""
        return self.value("encoder_delay_s")

    def apply(self, model: mujoco.MjModel) -> None:
        """Write the model parameters into a compiled model (before its first step)."""
        for name, value in self.parameters.items():
            write = PARAMETERS[name].write
            if write is not None:
                write(model, float(value))

    def as_dict(self) -> dict[str, Any]:
        """The YAML document of this calibration."""
        doc: dict[str, Any] = {
            "format": FORMAT,
            "version": VERSION,
            "model": MODEL_NAME,
            "parameters": {k: float(v) for k, v in self.parameters.items()},
        }
        if self.intervals:
            doc["intervals"] = {k: float(v) for k, v in self.intervals.items()}
        if self.undetermined:
            doc["undetermined"] = list(self.undetermined)
        if self.fit:
            doc["fit"] = dict(self.fit)
        return doc

    def to_yaml(self) -> str:
        """This calibration as a YAML document."""
        return str(yaml.safe_dump(self.as_dict(), sort_keys=False))

    @classmethod
    def from_dict(cls, doc: Any, source: str = "") -> LegCalibration:
        """Check and read a calibration document (as `as_dict` writes it).

        Raises:
            CalibrationError: wrong format, version or model, unknown parameter or value out of range.
        """
        parameters = check_document(doc, source or "calibration")
        return cls(
            parameters=dict(parameters),
            intervals={k: float(v) for k, v in (doc.get("intervals") or {}).items()},
            undetermined=tuple(doc.get("undetermined") or ()),
            fit=dict(doc.get("fit") or {}),
            source=source,
        )

    @classmethod
    def load(cls, name_or_path: str) -> LegCalibration:
        """Read a calibration file, or a packaged calibration by its name.

        Raises:
            CalibrationError: the file is missing, is not YAML, or holds an invalid calibration.
        """
        doc, source = read_document(name_or_path)
        return cls.from_dict(doc, source=source)


def model_values(model: mujoco.MjModel) -> dict[str, float]:
    """Every parameter's value in a compiled model (the sensors' parameters: 0)."""
    return {name: (p.read(model) if p.read is not None else 0.0) for name, p in PARAMETERS.items()}


__all__ = [
    "FORMAT",
    "MAX_ENCODER_DELAY_S",
    "PARAMETERS",
    "VERSION",
    "CalibrationError",
    "LegCalibration",
    "LegParameter",
    "model_values",
    "packaged_calibrations",
    "resolve_calibration_path",
]
