"""The learner's record of a run: its events (g2p.learning.run_events) and every inverse map."""

from __future__ import annotations

import json
import math
from collections.abc import Callable

import numpy as np
from rclpy.duration import Duration
from rclpy.node import Node
from std_msgs.msg import Header

from g2p.inverse_map import FitReport
from g2p.learning import run_events
from g2p.learning.attempt import AttemptOutcome
from g2p.learning.learner import Learner
from g2p.learning.limit_cycle import LimitCycleConfig, cycle_kinematics
from g2p.learning.run_events import Event
from g2p.plant import Recording
from g2p_interfaces.msg import InverseMapWeights, LearnerEvent
from g2p_ros.contract import EVENT_QOS, LEARNER_EVENTS, LEARNER_INVERSE_MAP, MAP_QOS
from g2p_ros.convert import inverse_map_weights_msg


class RunPublisher:
    """Publishes the run's events on `~/events` and its maps on `~/inverse_map` of `node`.

    Args:
        node: the learner node (its clock stamps every message).
        run_id: the run the messages belong to, asked for each message (the learner may adopt the
            recorder's).
    """

    def __init__(self, node: Node, run_id: Callable[[], str]) -> None:
        self._node = node
        self._run_id = run_id
        self._events = node.create_publisher(LearnerEvent, f"~/{LEARNER_EVENTS}", EVENT_QOS)
        self._maps = node.create_publisher(InverseMapWeights, f"~/{LEARNER_INVERSE_MAP}", MAP_QOS)

    def flush(self, timeout_s: float) -> bool:
        """Wait until every subscriber acknowledged every event and map; False on timeout."""
        wait = Duration(seconds=timeout_s)
        return all(p.wait_for_all_acked(wait) for p in (self._events, self._maps))

    def event(
        self,
        event: Event,
        phase: str = "",
        attempt: int = 0,
        features: np.ndarray | None = None,
        detail: dict[str, object] | None = None,
        **values: float,
    ) -> None:
        """One LearnerEvent; `values` set its figures (reward_mm, energy_j, ...), NaN when not given."""
        msg = LearnerEvent(
            header=Header(stamp=self._node.get_clock().now().to_msg()),
            run_id=self._run_id(),
            event=event.value,
            phase=phase,
            attempt=attempt,
            features=np.asarray(features if features is not None else [], dtype=np.float64),
            reward_mm=math.nan,
            energy_j=math.nan,
            tracking_mse_deg2=math.nan,
            tracking_rmse_rad=math.nan,
            best_reward_mm=math.nan,
            sigma=math.nan,
            detail=json.dumps(detail or {}),
        )
        for name, value in values.items():
            setattr(msg, name, float(value))
        self._events.publish(msg)

    def segment(self, event: Event, recording: Recording | None = None) -> None:
        """A babbling segment's start, or its end with where its ticks are (for reading the bag back)."""
        detail = run_events.segment_detail(recording) if recording is not None else {}
        self.event(event, phase="babbling", detail=detail)

    def attempt_start(
        self, phase: str, number: int, features: np.ndarray | None, cycle: LimitCycleConfig, control: str
    ) -> None:
        """An attempt's start, with one cycle of its desired angles (N x 2, rad) for live viewers."""
        desired = cycle_kinematics(features, cycle)[:, :2].tolist() if features is not None else None
        detail = run_events.attempt_start_detail(control, desired)
        self.event(Event.ATTEMPT_START, phase=phase, attempt=number, features=features, detail=detail)

    def attempt_end(
        self,
        phase: str,
        number: int,
        outcome: AttemptOutcome,
        sigma: float | None = None,
        best: float = math.nan,
    ) -> None:
        """An attempt's end, with its figures and where its ticks are."""
        self.event(
            Event.ATTEMPT_END,
            phase=phase,
            attempt=number,
            features=outcome.features,
            detail=run_events.attempt_end_detail(outcome),
            reward_mm=outcome.reward_mm,
            energy_j=outcome.energy_j,
            tracking_mse_deg2=outcome.tracking.mse_deg2,
            tracking_rmse_rad=outcome.tracking.rmse_rad,
            sigma=math.nan if sigma is None else sigma,
            best_reward_mm=best,
        )

    def inverse_map(self, learner: Learner, fit: FitReport | None) -> None:
        """The learner's current map; `fit` is the fit or refinement that made it (None: restored)."""
        msg = inverse_map_weights_msg(learner.inverse_map)
        msg.header = Header(stamp=self._node.get_clock().now().to_msg())
        msg.run_id = self._run_id()
        msg.refinement = learner.refinements
        msg.training_samples = len(learner.dataset) if fit is None else fit.n_train + fit.n_validation
        msg.validation_rmse = math.nan if fit is None else fit.validation_rmse
        self._maps.publish(msg)
