"""Load the leg's MJCF model, place the carriage, and find the elements the plant drives and reads."""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
from numpy.typing import NDArray

from g2p.plant import JOINT_NAMES, MOTOR_NAMES
from g2p.sim.calibration import LegCalibration
from g2p.sim.config import packaged_model_path
from g2p.sim.motor import MotorConstants

IntArray = NDArray[np.intp]

CARRIAGE_BODY = "carriage"
BELT_JOINT = "belt"
SPOOL_JOINTS = ("spool0", "spool1", "spool2")  # one per motor, in MOTOR_NAMES order
# Custom numerics holding the motor's electrical constants (see leg.xml and MotorConstants).
_NUMERICS = {
    "kt_nm_per_a": "motor_kt",
    "resistance_ohm": "motor_resistance",
    "max_current_a": "motor_max_current",
    "spool_radius_m": "spool_radius",
}
# Narrowest dead band of a tendon spring (m): far more slack than any posture can produce.
_MIN_DEAD_BAND_M = 0.5
# First-order actuator dynamics, act' = (ctrl - act) / lag: the motor current lag.
_FILTER_DYNAMICS = (int(mujoco.mjtDyn.mjDYN_FILTER), int(mujoco.mjtDyn.mjDYN_FILTEREXACT))


class ModelError(ValueError):
    """The MJCF model lacks an element the plant needs or its parameters are inconsistent."""


@dataclass(frozen=True)
class LegModel:
    """A compiled leg model and the addresses the plant uses.

    Attributes:
        model: the compiled MuJoCo model.
        motor: the motors' electrical constants (from the model's custom numerics).
        joint_qpos: qpos addresses of the proximal and distal joints, shape (2,).
        joint_dof: dof addresses of the proximal and distal joints, shape (2,).
        spool_qpos: qpos addresses of the three spool joints (M0, M1, M2), shape (3,).
        spool_dof: dof addresses of the three spool joints, shape (3,).
        belt_qpos: qpos address of the belt slide joint.
        belt_dof: dof address of the belt slide joint.
        motor_lag_s: first-order lag of the motor current (s), from the actuators' dynprm.
        carriage_body: id of the carriage body (the hip axis is its origin).
    """

    model: mujoco.MjModel
    motor: MotorConstants
    joint_qpos: IntArray
    joint_dof: IntArray
    spool_qpos: IntArray
    spool_dof: IntArray
    belt_qpos: int
    belt_dof: int
    motor_lag_s: float
    carriage_body: int


def _joint(model: mujoco.MjModel, name: str) -> int:
    jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
    if jid < 0:
        raise ModelError(f"model has no joint named {name!r}")
    return int(jid)


def _numeric(model: mujoco.MjModel, name: str) -> float:
    nid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, name)
    if nid < 0:
        raise ModelError(f"model has no custom numeric named {name!r}")
    return float(model.numeric_data[model.numeric_adr[nid]])


def packaged_numerics() -> dict[str, str]:
    """The packaged model's custom numerics by name: each one's MJCF line, its comment (the unit) included."""
    text = packaged_model_path().read_text()
    return {m[2]: m[1] for m in re.finditer(r'^\s*(<numeric name="([^"]+)".*?)\s*$', text, re.MULTILINE)}


def require_numerics(model: mujoco.MjModel, names: Iterable[str]) -> None:
    """Raise ModelError unless the compiled model has a custom numeric of each of `names`.

    The message names every one missing and gives the packaged model's lines for them, to copy into the
    model's `<custom>` block (a model written before some of them existed lacks them).
    """
    missing = [n for n in names if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, n) < 0]
    if not missing:
        return
    packaged = packaged_numerics()
    lines = "\n".join(f"    {packaged[n]}" for n in missing)
    raise ModelError(
        f"model lacks the custom numerics {', '.join(missing)}; copy the packaged model's values "
        f"({packaged_model_path()}) into its <custom> block:\n{lines}"
    )


def _check_actuators(model: mujoco.MjModel, motor: MotorConstants, spool_joints: list[int]) -> float:
    """Check each motor actuator drives its spool with torque Kt * I_max * act; return the motor lag (s)."""
    lags = []
    for name, jid in zip(MOTOR_NAMES, spool_joints, strict=True):
        aid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, name)
        if aid < 0:
            raise ModelError(f"model has no actuator named {name!r}")
        if aid != MOTOR_NAMES.index(name):
            raise ModelError(f"actuator {name!r} must be number {MOTOR_NAMES.index(name)}, is {aid}")
        if (
            model.actuator_trntype[aid] != int(mujoco.mjtTrn.mjTRN_JOINT)
            or model.actuator_trnid[aid, 0] != jid
        ):
            raise ModelError(f"actuator {name!r} must drive joint {SPOOL_JOINTS[aid]!r}")
        if model.actuator_dyntype[aid] not in _FILTER_DYNAMICS:
            raise ModelError(f"actuator {name!r} must have first-order (filter) dynamics: the motor lag")
        gain = float(model.actuator_gainprm[aid, 0])
        if not math.isclose(gain, motor.max_torque_nm, rel_tol=1e-9) or model.actuator_biastype[aid] != 0:
            raise ModelError(
                f"actuator {name!r}: gain {gain} N m must equal motor_kt * motor_max_current = "
                f"{motor.max_torque_nm} N m, with no bias"
            )
        lags.append(float(model.actuator_dynprm[aid, 0]))
    if len(set(lags)) != 1:
        raise ModelError(f"the three motors must share one lag, got {lags}")
    return lags[0]


def _check_tendons(model: mujoco.MjModel, motor: MotorConstants, spool_joints: list[int]) -> None:
    """Check tendon i is named after motor i, winds on spool i at the spool radius, and can only pull."""
    for i, (name, spool) in enumerate(zip(MOTOR_NAMES, spool_joints, strict=True)):
        tid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TENDON, name)
        if tid != i:
            raise ModelError(f"tendon {name!r} must exist and be number {i}, is {tid}")
        adr, num = int(model.tendon_adr[tid]), int(model.tendon_num[tid])
        coefs = {
            int(model.wrap_objid[w]): float(model.wrap_prm[w])
            for w in range(adr, adr + num)
            if model.wrap_type[w] == int(mujoco.mjtWrap.mjWRAP_JOINT)
        }
        if len(coefs) != num or not math.isclose(coefs.get(spool, 0.0), motor.spool_radius_m, rel_tol=1e-9):
            raise ModelError(
                f"tendon {name!r} must be a fixed tendon winding on {SPOOL_JOINTS[i]!r} with "
                f"coef = spool_radius = {motor.spool_radius_m} m"
            )
        # A tendon that only pulls: a spring with a dead band whose lower end is never reached (slack
        # carries no force), no damping, no length limit (each of these could push).
        low, high = model.tendon_lengthspring[tid]
        if high - low < _MIN_DEAD_BAND_M:
            raise ModelError(
                f"tendon {name!r}: springlength must be a dead band 'low high' at least "
                f"{_MIN_DEAD_BAND_M} m wide (tension only when stretched), got ({low}, {high})"
            )
        if model.tendon_stiffness[tid] <= 0 or model.tendon_damping[tid] != 0 or model.tendon_limited[tid]:
            raise ModelError(f"tendon {name!r} must have stiffness > 0, damping 0 and no length range")


def load_leg_model(
    path: Path,
    carriage_height_m: float,
    calibration: LegCalibration | None = None,
    numerics: Iterable[str] = (),
) -> LegModel:
    """Compile the MJCF at `path` with the carriage (hip axis) at `carriage_height_m` above the belt.

    `calibration`'s model parameters are written into the compiled model.

    Args:
        path: the MJCF file.
        carriage_height_m: the hip axis's height above the belt (m).
        calibration: model parameters to write into the compiled model.
        numerics: custom numerics the caller reads besides the motors' (the rig's limits: a missing one
            is named with the motors' missing ones, in one error).

    Raises:
        ModelError: a required element is missing or the motor parameters disagree (the message starts
            with `path`).
        ValueError: MuJoCo cannot parse or compile the file.
    """
    try:
        return _load_leg_model(path, carriage_height_m, calibration, numerics)
    except ModelError as err:
        raise ModelError(f"{path}: {err}") from err


def _load_leg_model(
    path: Path, carriage_height_m: float, calibration: LegCalibration | None, numerics: Iterable[str]
) -> LegModel:
    spec = mujoco.MjSpec.from_file(str(path))
    carriage = spec.body(CARRIAGE_BODY)
    if carriage is None:
        raise ModelError(f"model has no body named {CARRIAGE_BODY!r}")
    carriage.pos = [carriage.pos[0], carriage.pos[1], carriage_height_m]
    model = spec.compile()
    if calibration is not None:
        calibration.apply(model)
    require_numerics(model, (*_NUMERICS.values(), *numerics))
    try:
        motor = MotorConstants(**{field: _numeric(model, name) for field, name in _NUMERICS.items()})
    except ValueError as err:
        raise ModelError(f"invalid motor constants in the model: {err}") from err
    joints = [_joint(model, n) for n in JOINT_NAMES]
    spools = [_joint(model, n) for n in SPOOL_JOINTS]
    belt = _joint(model, BELT_JOINT)
    lag = _check_actuators(model, motor, spools)
    _check_tendons(model, motor, spools)
    return LegModel(
        model=model,
        motor=motor,
        joint_qpos=np.array([model.jnt_qposadr[j] for j in joints], dtype=np.intp),
        joint_dof=np.array([model.jnt_dofadr[j] for j in joints], dtype=np.intp),
        spool_qpos=np.array([model.jnt_qposadr[j] for j in spools], dtype=np.intp),
        spool_dof=np.array([model.jnt_dofadr[j] for j in spools], dtype=np.intp),
        belt_qpos=int(model.jnt_qposadr[belt]),
        belt_dof=int(model.jnt_dofadr[belt]),
        motor_lag_s=lag,
        carriage_body=int(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, CARRIAGE_BODY)),
    )
