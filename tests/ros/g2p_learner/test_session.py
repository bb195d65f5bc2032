"""The learner's session on an in-process rig: what it plays, how it numbers attempts, what it records.

The session publishes on a real rclpy node in its own Context; a subscription on that node reads the record
back. The rig is `PlantRig` over the plant that is the exact inverse of a known map
(tests/learning/test_attempt.py), so an attempt's figures are known by hand.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from g2p.learning.learner import LearnerConfig
from g2p.learning.limit_cycle import cycle_kinematics
from g2p.learning.run_events import Event
from g2p.plant import stamp_ns
from g2p.rig import PlantRig, RetryingRig, RigCancelled
from g2p_interfaces.msg import InverseMapWeights, LearnerEvent
from g2p_learner.config import LearnerNodeConfig
from g2p_learner.run_publisher import RunPublisher
from g2p_learner.session import LearningSession
from g2p_ros.contract import EVENT_QOS, LEARNER_EVENTS, LEARNER_INVERSE_MAP, MAP_QOS
from g2p_ros.convert import map_from_weights
from tests.learning.test_attempt import (
    BELT_MM_PER_TICK,
    CYCLE,
    ENERGY_J_PER_TICK,
    FEATURES,
    UNLIMITED,
    InverseMapPlant,
    N,
    known_map,
)

RUN_ID = "run-under-test"
END = "end of test"  # the detail of the last event a test publishes: everything before it has arrived
LEAD = LearnerConfig().preprocess.command_lead_ticks  # 3: the plant lags by as much


class Record:
    """A node in its own Context, the session's record published on it, and what that record carried."""

    def __init__(self) -> None:
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = Node("learner", namespace="/session_test", context=self.context)
        self.events: list[LearnerEvent] = []
        self.maps: list[InverseMapWeights] = []
        self.node.create_subscription(LearnerEvent, f"~/{LEARNER_EVENTS}", self.events.append, EVENT_QOS)
        self.node.create_subscription(
            InverseMapWeights, f"~/{LEARNER_INVERSE_MAP}", self.maps.append, MAP_QOS
        )
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.publisher: RunPublisher | None = None

    def session(self, learner: LearnerConfig | None = None) -> tuple[LearningSession, InverseMapPlant]:
        """A session with its own run id on a rig over a fresh plant."""
        plant = InverseMapPlant(delay=LEAD)
        config = LearnerNodeConfig(run_id=RUN_ID, cycle=CYCLE, learner=learner or LearnerConfig(seed=1))
        holder: list[LearningSession] = []
        self.publisher = RunPublisher(self.node, lambda: holder[0].run_id)
        rig = RetryingRig(PlantRig(plant, config=UNLIMITED), limit_s=1.0)
        holder.append(LearningSession(config, rig, self.publisher, threading.Event(), lambda _: None))
        return holder[0], plant

    def collect(self, maps: int) -> tuple[list[LearnerEvent], list[InverseMapWeights]]:
        """Everything published so far: closes the events with a marker and waits for `maps` maps."""
        assert self.publisher is not None
        self.publisher.event(Event.RUN_END, detail={"marker": END})
        deadline = 30.0
        while not (self.events and _detail(self.events[-1]).get("marker") == END and len(self.maps) >= maps):
            self.executor.spin_once(timeout_sec=0.1)
            deadline -= 0.1
            assert deadline > 0, f"record incomplete: {len(self.events)} events, {len(self.maps)} maps"
        return self.events[:-1], self.maps

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


def _detail(event: LearnerEvent) -> dict[str, Any]:
    detail: dict[str, Any] = json.loads(event.detail)
    return detail


@pytest.fixture
def record() -> Iterator[Record]:
    r = Record()
    yield r
    r.close()


def test_an_attempt_is_announced_played_and_recorded_with_its_known_figures(record: Record) -> None:
    session, plant = record.session()
    session.learner.inverse_map = known_map()
    progress: list[tuple[int, int]] = []
    outcome, fit = session.attempt(FEATURES, CYCLE, False, lambda d, t: progress.append((d, t)))
    assert fit is None and plant.resets == 1 and plant.ticks == N
    assert outcome.reward_mm == pytest.approx((N - 1) * BELT_MM_PER_TICK, rel=1e-12)
    assert outcome.energy_j == pytest.approx((N - 1) * ENERGY_J_PER_TICK, rel=1e-12)
    assert outcome.tracking.rmse_rad < 1e-10  # the learner plays the map's lead, which the plant lags
    assert progress[-1] == (N, N)
    events, maps = record.collect(maps=0)
    assert maps == []  # not refined: no new map
    start, end = events
    assert [(e.event, e.phase, e.attempt, e.run_id) for e in events] == [
        (Event.ATTEMPT_START.value, "attempt", 1, RUN_ID),
        (Event.ATTEMPT_END.value, "attempt", 1, RUN_ID),
    ]
    np.testing.assert_array_equal(start.features, FEATURES)
    np.testing.assert_array_equal(end.features, FEATURES)
    one_cycle = cycle_kinematics(FEATURES, CYCLE)[:, :2]
    assert _detail(start) == {"control": "open", "desired_cycle_rad": one_cycle.tolist()}
    assert len(_detail(start)["desired_cycle_rad"]) == 20  # 10 spokes x 2 ticks
    assert (end.reward_mm, end.energy_j) == (outcome.reward_mm, outcome.energy_j)
    assert (end.tracking_mse_deg2, end.tracking_rmse_rad) == (
        outcome.tracking.mse_deg2,
        outcome.tracking.rmse_rad,
    )
    assert np.isnan(end.sigma) and np.isnan(end.best_reward_mm)  # outside a run
    detail = _detail(end)
    assert detail["ticks"] == N and detail["control"] == "open"
    assert detail["first_tick_stamp_ns"] == stamp_ns(outcome.recording.t_s[0])
    np.testing.assert_array_equal(detail["desired_rad"], outcome.desired[:, :2])


@pytest.mark.slow  # the first fit imports torch: seconds
def test_attempts_are_numbered_from_one_and_each_refined_map_is_recorded(
    record: Record,
) -> None:
    session, _ = record.session()
    session.learner.inverse_map = known_map()
    refined = []
    for refine in (True, False, True, False):
        _, fit = session.attempt(FEATURES, CYCLE, refine, lambda d, t: None)
        refined.append(fit is not None)
    assert refined == [True, False, True, False]
    assert session.learner.refinements == 2
    events, maps = record.collect(maps=2)
    starts = [e.attempt for e in events if e.event == Event.ATTEMPT_START.value]
    ends = [e.attempt for e in events if e.event == Event.ATTEMPT_END.value]
    # Attempts are numbered 1, 2, ... whether they refined the map or not: one number, one attempt.
    assert starts == ends == [1, 2, 3, 4]
    assert [m.refinement for m in maps] == [1, 2]
    assert all(m.run_id == RUN_ID for m in maps)
    # The last map recorded is the learner's map, weight for weight.
    last = map_from_weights(maps[-1].arrays, maps[-1].format_version)
    for name, value in session.learner.inverse_map.to_arrays().items():
        np.testing.assert_array_equal(last.to_arrays()[name], value, err_msg=name)
    assert maps[-1].training_samples == len(session.learner.dataset)


@pytest.mark.slow  # the first fit imports torch: seconds
def test_babbling_announces_each_chunk_as_a_segment_then_records_the_fitted_map(record: Record) -> None:
    session, plant = record.session(LearnerConfig(seed=1, babbling_chunk_s=1.0))
    progress: list[tuple[int, int]] = []
    fit = session.babble(2.0, lambda d, t: progress.append((d, t)))
    ticks = 156  # 2 s at 78 Hz, in chunks of 78
    assert plant.ticks == ticks and progress[0] == (0, ticks) and progress[-1] == (ticks, ticks)
    chunks = session.learner.babbling_recordings
    assert [len(c) for c in chunks] == [78, 78]
    events, maps = record.collect(maps=1)
    assert [(e.event, e.phase) for e in events] == [
        (Event.PHASE_START.value, "babbling"),
        (Event.PHASE_END.value, "babbling"),
    ] * 2
    assert [_detail(e) for e in events] == [
        {},
        {"ticks": 78, "first_tick_stamp_ns": stamp_ns(chunks[0].t_s[0])},
        {},
        {"ticks": 78, "first_tick_stamp_ns": stamp_ns(chunks[1].t_s[0])},
    ]
    assert stamp_ns(chunks[1].t_s[0]) > stamp_ns(chunks[0].t_s[-1])  # the second chunk follows the first
    (fitted,) = maps
    assert fitted.refinement == 0 and fitted.run_id == RUN_ID
    assert fitted.training_samples == fit.n_train + fit.n_validation
    assert fitted.validation_rmse == fit.validation_rmse


def test_a_cancelled_attempt_ends_before_its_end_is_recorded(record: Record) -> None:
    session, _ = record.session()
    session.learner.inverse_map = known_map()
    session.cancel.set()
    with pytest.raises(RigCancelled):
        session.attempt(FEATURES, CYCLE, True, lambda d, t: None)
    assert session.learner.refinements == 0
    events, maps = record.collect(maps=0)
    assert [(e.event, e.attempt) for e in events] == [(Event.ATTEMPT_START.value, 1)]
    assert maps == []


def test_a_session_without_a_run_id_of_its_own_adopts_the_recorders() -> None:
    context = Context()
    rclpy.init(context=context)
    node = Node("learner", namespace="/session_test", context=context)
    try:
        record = RunPublisher(node, lambda: "")
        rig = RetryingRig(PlantRig(InverseMapPlant(), config=UNLIMITED), limit_s=1.0)
        own = LearningSession(LearnerNodeConfig(run_id="mine"), rig, record, threading.Event(), print)
        own.adopt(("recorders", "/bags/recorders"))
        assert (own.run_id, own.bag_path) == ("mine", "")
        none = LearningSession(
            LearnerNodeConfig(bag_path="/data/bags"), rig, record, threading.Event(), print
        )
        generated = none.run_id
        assert generated
        none.adopt(None)
        assert none.run_id == generated
        none.adopt(("recorders", "/bags/recorders"))
        assert (none.run_id, none.bag_path) == ("recorders", "/data/bags")  # its own bag path is kept
        other = LearningSession(LearnerNodeConfig(), rig, record, threading.Event(), print)
        other.adopt(("", "/bags/x"))  # a recorder with no run yet: the session keeps its id
        assert other.run_id and other.bag_path == "/bags/x"
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)
