"""The learner node: babbling, attempts, full G2P runs and tracking experiments as ROS 2 actions.

It drives whatever rig serves `run_activations`, `run_trajectory` (closed loop) and `reset` in its
namespace (simulator or hardware, chosen by remapping), publishes every event and every inverse map for
the recorder, and keeps the algorithm in the core library (g2p.learning.learner, g2p.learning.experiments);
its session (g2p_learner.session) plays it on the rig, the node validates goals and converts messages.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.action.server import ServerGoalHandle
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter

from g2p.inverse_map import FitCancelled
from g2p.learning import run_events
from g2p.learning.experiments import AttemptReport, TrackingReport, TrajectoryRefinement, treadmill_result
from g2p.learning.learner import LearnerConfig
from g2p.learning.limit_cycle import LimitCycleConfig
from g2p.learning.run_events import Event
from g2p.learning.search import SearchConfig
from g2p.rig import DEFAULT_NAMESPACE, RetryingRig, RigCancelled, RigError, RigUnreachable
from g2p_interfaces.action import Attempt, Babble, Learn, Track
from g2p_learner import goals
from g2p_learner.config import LearnerNodeConfig
from g2p_learner.recorder_link import RecorderLink
from g2p_learner.run_publisher import RunPublisher
from g2p_learner.session import LearningSession, Step
from g2p_ros.contract import action_name, wait_all
from g2p_ros.params import config_as_dict, declare_config, parameter_names, publish_config
from g2p_ros.rig_client import RigClient

# The search's fields the node sets from the cycle's (LearnerNodeConfig.search_config), not parameters.
_SEARCH_FROM_CYCLE = ("n_features", "feature_low", "feature_high")


def node_parameters() -> list[str]:
    """The parameters LearnerNode declares besides rclpy's (bringup checks its `--set` against them)."""
    return [
        *parameter_names(LearnerNodeConfig, exclude=("search",)),
        *parameter_names(SearchConfig, "search.", exclude=_SEARCH_FROM_CYCLE),
    ]


class LearnerNode(Node):
    """Hosts the babble, attempt, learn and track actions; one goal at a time."""

    def __init__(self, parameter_overrides: list[Parameter] | None = None) -> None:
        super().__init__("learner", namespace=DEFAULT_NAMESPACE, parameter_overrides=parameter_overrides)
        base = declare_config(self, LearnerNodeConfig, exclude=("learner", "cycle", "search"))
        self.config = replace(
            base,
            learner=declare_config(self, LearnerConfig, "learner."),
            cycle=declare_config(self, LimitCycleConfig, "cycle."),
            search=declare_config(self, SearchConfig, "search.", exclude=_SEARCH_FROM_CYCLE),
        )
        cfg = self.config
        # A reset waited for while the rig is lost must not outlast the limit (it blocks until answered).
        reset_timeout_s = min(cfg.rig_reset_timeout_s, cfg.rig_lost_limit_s)
        self.client = RigClient(self, cfg.rig_timeout_s, cfg.rig_silence_s, reset_timeout_s)
        self.watches = list(self.client.watches)
        self.recorder = RecorderLink(self, cfg.recorder_node) if cfg.recorder_node else None
        if self.recorder is not None:
            self.watches.append(self.recorder.watch)
        self._busy = False
        self._busy_lock = threading.Lock()
        self._cancel = threading.Event()
        self.record = RunPublisher(self, lambda: self.session.run_id)
        rig = RetryingRig(self.client, cfg.rig_lost_limit_s, on_event=self._rig_event)
        self.session = LearningSession(cfg, rig, self.record, self._cancel, self.get_logger().info)
        self._config_pub = publish_config(self, config_as_dict(self.config))

        group = ReentrantCallbackGroup()
        self._servers = [
            ActionServer(
                self,
                action,
                action_name(self, name),
                execute_callback=self._guarded(action, execute),
                goal_callback=self._goal_callback(validate),
                cancel_callback=self._on_cancel,
                callback_group=group,
            )
            for action, name, execute, validate in (
                (Babble, "babble", self._execute_babble, goals.check_babble),
                (Attempt, "attempt", self._execute_attempt, self._check_attempt),
                (Learn, "learn", self._execute_learn, goals.check_learn),
                (Track, "track", self._execute_track, self._check_track),
            )
        ]

    def stop_goals(self, timeout_s: float) -> bool:
        """Cancel whatever goal runs (the rig drops to baseline) and wait until it ended; False on timeout."""
        self._cancel.set()
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            with self._busy_lock:
                if not self._busy:
                    return True
            time.sleep(0.05)
        return False

    def destroy_node(self) -> None:
        """Destroy the action servers and the rig client, then the node."""
        for server in self._servers:
            server.destroy()
        self.client.destroy()
        super().destroy_node()

    def flush_events(self, timeout_s: float) -> bool:
        """Wait until the recorder acknowledged every event and map (across a slow link); False on timeout."""
        return self.record.flush(timeout_s)

    def _rig_event(self, event: str, detail: dict[str, Any]) -> None:
        """The rig was lost or came back (RetryingRig): log it and record it."""
        if event == Event.RIG_LOST:
            self.get_logger().warning(
                f"rig lost during {detail['call']}: {detail['error']}; waiting up to "
                f"{self.config.rig_lost_limit_s:g} s for it to answer again"
            )
        else:
            self.get_logger().info(
                f"rig back after {detail['downtime_s']:.1f} s; the lost sequence is played again from rest"
            )
        self.record.event(Event(event), detail=detail)

    def _resume_hint(self) -> str:
        where = self.session.bag_path or "bags/<run>"
        return (
            f"everything up to the last completed attempt is recorded; continue the run with: "
            f"ros2 run g2p_learner learn --resume {where}"
        )

    # Goal validation ---------------------------------------------------------------------------------

    def _goal_callback(self, validate: Callable[[object], None]) -> Callable[[object], GoalResponse]:
        def callback(goal: object) -> GoalResponse:
            try:
                validate(goal)
            except goals.GoalRejected as err:
                self.get_logger().warning(f"goal rejected: {err}")
                return GoalResponse.REJECT
            with self._busy_lock:
                if self._busy:
                    self.get_logger().warning("goal rejected: another goal is running")
                    return GoalResponse.REJECT
                self._busy = True
            return GoalResponse.ACCEPT

        return callback

    def _check_attempt(self, goal: Attempt.Goal) -> None:
        goals.check_attempt(goal, self.config.cycle, self.session.learner)

    def _check_track(self, goal: Track.Goal) -> None:
        goals.check_track(goal, self.config.air_cycle, self.session.learner)

    def _on_cancel(self, goal_handle: ServerGoalHandle) -> CancelResponse:
        self._cancel.set()  # the rig drops to baseline within one tick; the goal ends between steps
        return CancelResponse.ACCEPT

    # Execution ---------------------------------------------------------------------------------------

    def _guarded(self, action: type, execute: Callable[[ServerGoalHandle], object]) -> Callable[..., object]:
        """Run a goal; a cancel or rig failure ends it cleanly with a message; always free the learner."""

        def run(goal_handle: ServerGoalHandle) -> object:
            self._cancel.clear()
            try:
                missing = wait_all(self.watches, self.config.rig_timeout_s, self._cancel)
                self._check_cancel(goal_handle)
                if missing:
                    raise RigError(
                        f"not on the graph after {self.config.rig_timeout_s:g} s: {', '.join(missing)}"
                    )
                self.session.adopt(self.recorder.run() if self.recorder is not None else None)
                return execute(goal_handle)
            except (RigCancelled, FitCancelled) as err:
                self.record.event(Event.RUN_END, detail={run_events.CANCELLED: str(err)})
                goal_handle.canceled()
                return action.Result(message=f"cancelled: {err}")
            except RigUnreachable as err:
                message = f"{err}; {self._resume_hint()}" if action is Learn else str(err)
                self.get_logger().error(f"{action.__name__} goal aborted: {message}")
                self.record.event(
                    Event.RUN_END,
                    detail={run_events.ERROR: str(err), run_events.RESUME: self.session.bag_path},
                )
                goal_handle.abort()
                return action.Result(message=message)
            except (RigError, ValueError) as err:
                self.get_logger().error(f"{action.__name__} goal aborted: {err}")
                self.record.event(Event.RUN_END, detail={run_events.ERROR: str(err)})
                goal_handle.abort()
                return action.Result(message=str(err))
            finally:
                with self._busy_lock:
                    self._busy = False

        return run

    def _check_cancel(self, goal_handle: ServerGoalHandle) -> None:
        if goal_handle.is_cancel_requested or self._cancel.is_set():
            raise RigCancelled("cancel requested")

    def _execute_babble(self, goal_handle: ServerGoalHandle) -> Babble.Result:
        def progress(done: int, total: int) -> None:
            goal_handle.publish_feedback(Babble.Feedback(progress=done / total, samples_done=done))

        fit = self.session.babble(goal_handle.request.duration_s or None, progress)
        goal_handle.succeed()
        return Babble.Result(
            sample_count=len(self.session.learner.dataset), validation_rmse=fit.validation_rmse
        )

    def _execute_attempt(self, goal_handle: ServerGoalHandle) -> Attempt.Result:
        goal = goal_handle.request
        cycle = replace(self.config.cycle, n_cycles=goal.cycles) if goal.cycles else self.config.cycle

        def progress(done: int, total: int) -> None:
            goal_handle.publish_feedback(
                Attempt.Feedback(stage="playing", ticks_done=done, ticks_total=total)
            )

        outcome, fit = self.session.attempt(
            np.asarray(goal.features), cycle, not goal.skip_refinement, progress
        )
        goal_handle.succeed()
        return Attempt.Result(
            reward_mm=outcome.reward_mm,
            energy_j=outcome.energy_j,
            tracking_mse_deg2=outcome.tracking.mse_deg2,
            tracking_rmse_rad=outcome.tracking.rmse_rad,
            refined=fit is not None,
        )

    def _execute_learn(self, goal_handle: ServerGoalHandle) -> Learn.Result:
        goal = goal_handle.request
        session = self.session
        if goal.resume_bag:
            run, fit = session.resume(goal.resume_bag, self.resolve_topic_name("~/config")), None
        else:
            search = self.config.search_config
            search = replace(
                search,
                threshold_mm=goal.threshold_mm or search.threshold_mm,
                max_exploration_attempts=goal.max_exploration_attempts or search.max_exploration_attempts,
                exploitation_attempts=goal.exploitation_attempts or search.exploitation_attempts,
            )

            def progress(done: int, total: int) -> None:
                goal_handle.publish_feedback(
                    Learn.Feedback(
                        phase="babbling",
                        babbling_progress=done / total,
                        reward_mm=math.nan,
                        best_reward_mm=math.nan,
                    )
                )

            run, fit = session.start_run(search, goal.dataset_bag, goal.babbling_duration_s, progress)
        session.checkpoint(run)

        def attempt_done(report: AttemptReport) -> None:
            best, sigma = report.best_reward_mm, report.sigma
            self.record.attempt_end(report.phase.value, report.number, report.outcome, sigma=sigma, best=best)
            session.checkpoint(run)
            goal_handle.publish_feedback(
                Learn.Feedback(
                    phase=report.phase.value,
                    babbling_progress=1.0,
                    attempt=report.number,
                    reward_mm=report.outcome.reward_mm,
                    best_reward_mm=best,
                    sigma=sigma or 0.0,
                )
            )

        def upcoming() -> Step:
            return Step(run.search.phase.value, len(run.search.history) + 1, run.next_features())

        session.run_steps(run, upcoming, attempt_done, lambda: self._check_cancel(goal_handle))
        result = treadmill_result(run, fit)
        summary = {
            "crossed_threshold": result.crossed_threshold,
            "best_reward_mm": result.best_reward_mm,
            "best_features": result.best_features.tolist(),
            "exploration_attempts": result.exploration_attempts,
            "exploitation_attempts": result.exploitation_attempts,
        }
        self.record.event(Event.RUN_END, detail=summary)
        goal_handle.succeed()
        return Learn.Result(
            best_features=result.best_features,
            best_reward_mm=result.best_reward_mm,
            crossed_threshold=result.crossed_threshold,
            exploration_attempts=result.exploration_attempts,
            exploitation_attempts=result.exploitation_attempts,
            run_id=session.run_id,
            bag_path=session.bag_path,
        )

    def _execute_track(self, goal_handle: ServerGoalHandle) -> Track.Result:
        goal = goal_handle.request
        experiment, upcoming = self.session.tracking_experiment(
            goal.mode == Track.Goal.MODE_REFINE_ONE,
            np.asarray(goal.features),
            goal.refinements,
            goal.train_trajectories,
            goal.test_trajectories,
        )

        def step_done(report: TrackingReport) -> None:
            if report.outcome is not None:
                self.record.attempt_end("tracking", report.number, report.outcome)
            goal_handle.publish_feedback(
                Track.Feedback(
                    stage=report.stage, index=report.number, tracking_mse_deg2=report.tracking.mse_deg2
                )
            )

        self.session.run_steps(experiment, upcoming, step_done, lambda: self._check_cancel(goal_handle))
        goal_handle.succeed()
        if isinstance(experiment, TrajectoryRefinement):
            return Track.Result(attempt_mse_deg2=[o.tracking.mse_deg2 for o in experiment.outcomes])
        result = experiment.result()
        return Track.Result(
            babbling_map_mse_deg2=[e.mse_deg2 for e in result.babbling_map],
            refined_map_mse_deg2=[e.mse_deg2 for e in result.refined_map],
        )
