"""The run events' names and the details the bag readers rely on, built from known inputs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from g2p.learning import run_events
from g2p.learning.attempt import AttemptOutcome, TrackingError
from g2p.learning.run_events import Event, attempt_end_detail, attempt_start_detail, segment_detail
from g2p.plant import Recording, TickSample
from g2p.rig.closed_loop import ControlMode


def recording(t_s: list[float]) -> Recording:
    """Ticks at the given stamps, all else zero."""
    z2, z3 = np.zeros(2), np.zeros(3)
    return Recording.from_samples([TickSample(t, z3, z2, z2, 0.0, 0.0, z3, z3, z3) for t in t_s])


def outcome(control: ControlMode, correction: np.ndarray | None = None) -> AttemptOutcome:
    """Three ticks from t = 2 s, desired angles (k, -k) with velocities and accelerations beside them."""
    desired = np.array([[0.0, -0.0, 9, 9, 9, 9], [1.0, -1.0, 9, 9, 9, 9], [2.0, -2.0, 9, 9, 9, 9]])
    rec = recording([2.0, 2.0128205128, 2.0256410256])
    return AttemptOutcome(
        features=np.full(10, 0.5),
        desired=desired,
        activations=np.full((3, 3), 0.2),
        recording=rec,
        reward_mm=12.5,
        energy_j=3.0,
        tracking=TrackingError(1.0, 0.01),
        control=control,
        correction_rad_s=correction,
    )


def test_the_event_names_are_the_recorded_strings() -> None:
    assert {e.name: e.value for e in Event} == {
        "RUN_START": "run_start",
        "PHASE_START": "phase_start",
        "PHASE_END": "phase_end",
        "ATTEMPT_START": "attempt_start",
        "ATTEMPT_END": "attempt_end",
        "CHECKPOINT": "checkpoint",
        "RIG_LOST": "rig_lost",
        "RIG_BACK": "rig_back",
        "RUN_END": "run_end",
    }
    assert Event("attempt_end") is Event.ATTEMPT_END  # a reader's string gives the event back
    assert Event.RIG_LOST == "rig_lost"  # and compares equal to it (the rig's own event names)
    with pytest.raises(ValueError):
        Event("attempt")


def test_the_detail_keys_are_the_documented_strings() -> None:
    keys = {
        "CONTROL": "control",
        "DESIRED_CYCLE_RAD": "desired_cycle_rad",
        "DESIRED_RAD": "desired_rad",
        "CORRECTION_RAD_S": "correction_rad_s",
        "TICKS": "ticks",
        "FIRST_TICK_STAMP_NS": "first_tick_stamp_ns",
        "CHECKPOINT": "checkpoint",
        "SEARCH": "search",
        "CANCELLED": "cancelled",
        "ERROR": "error",
        "RESUME": "resume",
    }
    assert {name: getattr(run_events, name) for name in keys} == keys


def test_a_segment_is_its_tick_count_and_its_first_ticks_stamp_in_ns() -> None:
    # 1/78 s is 12,820,512.82 ns: the stamp rounds to the nearest ns, as a ROS header carries it.
    detail = segment_detail(recording([1 / 78, 2 / 78, 3 / 78, 4 / 78]))
    assert detail == {"ticks": 4, "first_tick_stamp_ns": 12_820_513}
    assert segment_detail(recording([5.0])) == {"ticks": 1, "first_tick_stamp_ns": 5_000_000_000}


def test_an_attempt_start_carries_its_control_and_the_desired_cycle_when_known() -> None:
    assert attempt_start_detail("open", None) == {"control": "open"}
    cycle = [[0.0, -0.6], [0.1, -0.5]]
    assert attempt_start_detail("closed", cycle) == {"control": "closed", "desired_cycle_rad": cycle}


def test_an_open_loop_attempt_end_carries_the_desired_angles_and_where_its_ticks_are() -> None:
    detail = attempt_end_detail(outcome(ControlMode.OPEN))
    assert detail == {
        "desired_rad": [[0.0, -0.0], [1.0, -1.0], [2.0, -2.0]],  # angles only, not the derivatives
        "ticks": 3,
        "first_tick_stamp_ns": 2_000_000_000,
        "control": "open",
    }


def test_a_closed_loop_attempt_end_also_carries_the_corrections() -> None:
    correction = np.array([[0.0, 0.0], [0.5, -0.25], [1.0, -0.5]])
    detail = attempt_end_detail(outcome(ControlMode.CLOSED, correction))
    assert detail["control"] == "closed"
    assert detail["correction_rad_s"] == [[0.0, 0.0], [0.5, -0.25], [1.0, -0.5]]
    assert detail["ticks"] == 3


@pytest.mark.parametrize(
    "detail",
    [
        segment_detail(recording([0.1, 0.2])),
        attempt_start_detail("open", [[0.0, -0.6]]),
        attempt_end_detail(outcome(ControlMode.OPEN)),
        attempt_end_detail(outcome(ControlMode.CLOSED, np.ones((3, 2)))),
    ],
)
def test_every_detail_survives_json_as_it_is(detail: dict[str, object]) -> None:
    text = json.dumps(detail, allow_nan=False)  # plain Python numbers and lists only
    assert json.loads(text) == detail
    assert all(type(v) is not np.ndarray and not isinstance(v, np.generic) for v in detail.values())
