"""The learner's recorded messages as plain data: LearnerEvent and InverseMapWeights."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from g2p.bags.ticks import header_stamp_ns

LEARNER_EVENT_TYPE = "g2p_interfaces/msg/LearnerEvent"
INVERSE_MAP_TYPE = "g2p_interfaces/msg/InverseMapWeights"
CONFIG_TYPE = "std_msgs/msg/String"
CONFIG_SUFFIX = "/config"

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class RunEvent:
    """One LearnerEvent (see g2p_interfaces/msg/LearnerEvent.msg for the meaning of each field).

    Attributes:
        stamp_ns: header stamp (ns, the learner's clock).
        log_time_ns: recording time (ns, the recorder's clock).
        run_id: the learning run.
        event: "run_start", "phase_start", "phase_end", "attempt_start", "attempt_end", "refined", "run_end".
        phase: "babbling", "exploration", "exploitation", "tracking", "testing" or "".
        attempt: attempt number, 1-based (0 when not about an attempt).
        features: limit-cycle features, shape (10,) or (0,).
        reward_mm: belt travel (mm), NaN when not measured.
        energy_j: electrical energy (J), NaN when not measured.
        tracking_mse_deg2: tracking MSE (deg^2, second half, joints summed), NaN when not measured.
        tracking_rmse_rad: tracking RMSE (rad), NaN when not measured.
        best_reward_mm: best reward so far (mm).
        sigma: exploitation standard deviation.
        detail: the detail JSON object ({} when empty or not an object).
    """

    stamp_ns: int
    log_time_ns: int
    run_id: str
    event: str
    phase: str
    attempt: int
    features: FloatArray
    reward_mm: float
    energy_j: float
    tracking_mse_deg2: float
    tracking_rmse_rad: float
    best_reward_mm: float
    sigma: float
    detail: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class InverseMapSnapshot:
    """One InverseMapWeights message: the inverse map after a fit or refinement.

    Attributes:
        stamp_ns: header stamp (ns).
        run_id: the learning run.
        refinement: 0 for the fit on babbling data, k after the k-th refinement.
        format_version: version of the array layout.
        arrays: name -> array, shaped as recorded.
        training_samples: samples the map was trained on.
        validation_rmse: held-out RMSE (activation units).
    """

    stamp_ns: int
    run_id: str
    refinement: int
    format_version: int
    arrays: dict[str, FloatArray]
    training_samples: int
    validation_rmse: float


def run_event(msg: Any, log_time_ns: int) -> RunEvent:
    """A decoded LearnerEvent message as a RunEvent."""
    return RunEvent(
        stamp_ns=header_stamp_ns(msg.header),
        log_time_ns=log_time_ns,
        run_id=str(msg.run_id),
        event=str(msg.event),
        phase=str(msg.phase),
        attempt=int(msg.attempt),
        features=np.asarray(msg.features, dtype=np.float64),
        reward_mm=float(msg.reward_mm),
        energy_j=float(msg.energy_j),
        tracking_mse_deg2=float(msg.tracking_mse_deg2),
        tracking_rmse_rad=float(msg.tracking_rmse_rad),
        best_reward_mm=float(msg.best_reward_mm),
        sigma=float(msg.sigma),
        detail=parse_detail(str(msg.detail)),
    )


def parse_detail(text: str) -> dict[str, Any]:
    """The detail JSON object of an event; {} when empty, and {"unparsed": text} when not a JSON object."""
    if not text.strip():
        return {}
    try:
        value = json.loads(text)
    except json.JSONDecodeError:
        return {"unparsed": text}
    return value if isinstance(value, dict) else {"unparsed": text}


def inverse_map_snapshot(msg: Any) -> InverseMapSnapshot:
    """A decoded InverseMapWeights message as a snapshot.

    Raises:
        ValueError: an array's data does not fit its shape.
    """
    arrays = {}
    for array in msg.arrays:
        data = np.asarray(array.data, dtype=np.float64)
        shape = tuple(int(n) for n in array.shape)
        if math.prod(shape) != data.size:
            raise ValueError(
                f"inverse map array {array.name!r}: shape {shape} does not fit {data.size} values"
            )
        arrays[str(array.name)] = data.reshape(shape)
    return InverseMapSnapshot(
        stamp_ns=header_stamp_ns(msg.header),
        run_id=str(msg.run_id),
        refinement=int(msg.refinement),
        format_version=int(msg.format_version),
        arrays=arrays,
        training_samples=int(msg.training_samples),
        validation_rmse=float(msg.validation_rmse),
    )
