"""Training data from a recorded run: babbling and attempts as Recordings, the latest map (known answers)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import fields, replace
from pathlib import Path

import numpy as np
import pytest

from g2p.bags import BagReadError, load_run, load_training_data
from g2p.description.urdf import leg_urdf, packaged_leg_description
from g2p.plant import Recording
from tests.bags.bagdata import TICK_NS, Messages, SyntheticRun, TickPlan, tick_values, write_plan


def expected(ticks: list[int]) -> Recording:
    rows = [tick_values(k) for k in ticks]
    return Recording(**{name: np.array([r[name] for r in rows]) for name in rows[0]})


def assert_same(got: Recording, want: Recording) -> None:
    assert len(got) == len(want)
    for f in fields(Recording):
        np.testing.assert_array_equal(getattr(got, f.name), getattr(want, f.name), err_msg=f.name)


@pytest.fixture
def run(synthetic_run: Callable[..., SyntheticRun]) -> SyntheticRun:
    return synthetic_run()


def test_babbling_segment_has_the_stated_tick_count(run: SyntheticRun) -> None:
    data = load_training_data(run.path)
    assert len(data.babbling) == 1
    assert_same(data.babbling[0], expected(run.babbling_ticks))  # the 20 idle ticks after it are left out


def test_each_attempt_is_its_own_ticks(run: SyntheticRun) -> None:
    data = load_training_data(run.path)
    assert len(data.attempts) == len(run.attempt_ticks)
    for recording, ticks in zip(data.attempts, run.attempt_ticks.values(), strict=True):
        assert_same(recording, expected(ticks))


def test_latest_inverse_map(run: SyntheticRun) -> None:
    data = load_training_data(run.path)
    assert data.inverse_map is not None
    assert data.inverse_map.keys() == {*run.maps[-1].keys(), "format_version"}
    assert data.inverse_map["format_version"].tolist() == [1.0]  # the message's field, as to_arrays gives it
    for name, array in run.maps[-1].items():
        np.testing.assert_array_equal(data.inverse_map[name], array)


def test_run_data_events_attempts_and_configs(run: SyntheticRun) -> None:
    data = load_run(run.path)
    assert data.run_id == "run-1"
    assert [e.event for e in data.events][:3] == ["run_start", "phase_start", "phase_end"]
    assert [a.attempt for a in data.attempts] == [1, 2, 3, 4, 5]
    assert [a.phase for a in data.attempts] == [run.phases[k] for k in range(1, 6)]
    assert [a.reward_mm for a in data.attempts] == [run.rewards[k] for k in range(1, 6)]
    assert [a.energy_j for a in data.attempts] == [run.energies[k] for k in range(1, 6)]
    first = data.attempts[0]
    assert first.desired_position_rad is not None
    np.testing.assert_allclose(first.desired_position_rad, first.recording.position_rad - 0.01)
    assert [m.refinement for m in data.inverse_maps] == [0, 1, 2, 3, 4, 5]
    assert data.configs == {"/leg/learner/config": {"search": {"threshold_mm": 64.0}, "run_id": "run-1"}}
    assert data.ticks.incomplete == 1  # tick 210 lacks its joint_states message
    assert len(data.ticks.recording) == 200 + 20 + 5 * (10 + 50) - 1


def test_without_explicit_bounds_the_event_stamps_bound_segments(
    synthetic_run: Callable[..., SyntheticRun],
) -> None:
    run = synthetic_run(skip_joint_state_of=None)
    data = load_run(run.path)
    # phase_end says how many ticks babbling played; attempts: as many ticks as desired_rad has rows
    assert len(data.babbling) == 200
    assert [len(a.recording) for a in data.attempts] == [50] * 5
    assert data.ticks.incomplete == 0


def test_other_namespace_has_no_rig_ticks(run: SyntheticRun) -> None:
    data = load_run(run.path, rig_namespace="/other")  # falls back to the only topic of each rig type
    assert len(data.ticks.recording) == 200 + 20 + 5 * 60 - 1


def planned(played: list[tuple[int, int]]) -> Recording:
    """The expected recording of scripted ticks: values of tick_values(k), stamps as scripted."""
    want = expected([k for _, k in played])
    return replace(want, t_s=np.array([stamp * 1e-9 for stamp, _ in played]))


def test_fast_simulation_timeline(tmp_path: Path, messages: Messages) -> None:
    """Like the learner against the fast simulator: events carry the last tick's stamp, resets repeat it."""
    plan, stamp = TickPlan(), 0
    plan.tick(stamp, 0)  # the rig's first sample, at rest
    plan.event(stamp, "phase_start", phase="babbling")
    plan.tick(stamp, 1)  # reset before babbling: the same stamp (sim time does not advance on a reset)
    k = 2
    for _ in range(30):
        stamp += TICK_NS
        plan.tick(stamp, k, "babbling")
        k += 1
    plan.event(stamp, "phase_end", phase="babbling", detail={"samples": 999})  # no tick count
    for attempt, lag in ((1, 0), (2, 1)):
        plan.event(stamp, "attempt_start", phase="exploration", attempt=attempt)
        plan.tick(stamp, k)  # reset: the stamp of the previous tick
        k += 1
        for _ in range(20):
            stamp += TICK_NS
            plan.tick(stamp, k, f"attempt {attempt}")
            k += 1
        # attempt 2: the learner's clock is one tick behind when it sends attempt_end
        plan.event(
            stamp - lag * TICK_NS,
            "attempt_end",
            phase="exploration",
            attempt=attempt,
            detail={"desired_rad": [[0.0, 0.0]] * 20},
        )
    write_plan(tmp_path / "fast", messages, plan)
    data = load_training_data(tmp_path / "fast")
    assert len(data.babbling) == 1
    assert_same(data.babbling[0], planned(plan.played["babbling"]))
    assert len(data.attempts) == 2
    for attempt, recording in enumerate(data.attempts, start=1):
        assert_same(recording, planned(plan.played[f"attempt {attempt}"]))


def test_first_tick_stamp_bounds_an_attempt_on_hardware(tmp_path: Path, messages: Messages) -> None:
    """Hardware: the rig ticks at baseline between sequences; attempt_end names the first played tick."""
    plan, stamp, k = TickPlan(), 10, 0
    plan.event(5, "attempt_start", phase="exploration", attempt=1)
    for segment, n in ((None, 8), ("attempt", 25), (None, 3)):  # reset and idle, the attempt, idle again
        for _ in range(n):
            stamp += TICK_NS
            plan.tick(stamp, k, segment)
            k += 1
    first = plan.played["attempt"][0][0]
    plan.event(
        stamp + 1,
        "attempt_end",
        phase="exploration",
        attempt=1,
        detail={"first_tick_stamp_ns": first, "ticks": 25},
    )
    write_plan(tmp_path / "hw", messages, plan)
    (attempt,) = load_training_data(tmp_path / "hw").attempts
    assert_same(attempt, planned(plan.played["attempt"]))


def test_leg_description_is_the_last_robot_description(synthetic_run: Callable[..., SyntheticRun]) -> None:
    packaged = packaged_leg_description()
    ours = replace(packaged, hip_height_m=0.5, thigh=replace(packaged.thigh, length_m=0.25))
    run = synthetic_run(robot_descriptions=(leg_urdf(packaged), leg_urdf(ours)))
    assert load_run(run.path).leg_description == ours


def test_no_robot_description_no_leg_description(run: SyntheticRun) -> None:
    assert load_run(run.path).leg_description is None


def test_bad_robot_description_is_a_read_error(synthetic_run: Callable[..., SyntheticRun]) -> None:
    run = synthetic_run(robot_descriptions=("<robot name='g2p_leg'>",))
    with pytest.raises(BagReadError) as caught:
        load_run(run.path)
    message = str(caught.value)
    assert message.startswith(str(run.path / f"{run.path.name}.mcap"))
    assert "/leg/robot_description" in message and "not XML" in message
