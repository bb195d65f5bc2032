"""The learner node: babbling, attempts, full G2P runs and tracking experiments as ROS 2 actions.

It drives whatever rig serves `run_activations`, `run_trajectory` (closed loop) and `reset` in its
namespace (simulator or hardware, chosen by remapping), publishes every event and every inverse map for
the recorder, and keeps the algorithm in the core library (g2p.learner, g2p.experiments).
"""

from __future__ import annotations

import json
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from datetime import datetime, timezone
from typing import Any

import numpy as np
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.action.server import ServerGoalHandle
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter

from g2p import run_events
from g2p.bags.runs import new_run_id
from g2p.checkpoint import capture
from g2p.config import require, require_positive
from g2p.experiments import (
    AttemptReport,
    Experiment,
    Generalization,
    TrackingReport,
    TrajectoryRefinement,
    TreadmillRun,
    random_features,
    treadmill_result,
)
from g2p.inverse_map import FitCancelled, FitReport
from g2p.learner import Learner, LearnerConfig
from g2p.limit_cycle import AIR_FEATURE_BOUNDS, LimitCycleConfig
from g2p.plant import Recording
from g2p.rig import (
    DEFAULT_NAMESPACE,
    ProgressCallback,
    RetryingRig,
    RigCancelled,
    RigError,
    RigUnreachable,
)
from g2p.run_events import Event
from g2p.search import SearchConfig
from g2p.seeds import seed_streams
from g2p_interfaces.action import Attempt, Babble, Learn, Track
from g2p_learner import goals
from g2p_learner.recorder_link import RecorderLink
from g2p_learner.run_publisher import RunPublisher
from g2p_ros.contract import action_name, wait_all
from g2p_ros.params import config_as_dict, declare_config, publish_config
from g2p_ros.rig_client import RigClient


@dataclass(frozen=True)
class LearnerNodeConfig:
    """The learner node's settings.

    Attributes:
        run_id: identifier of the next learning run; "" takes the recorder's (`recorder_node`), else
            generates one (UTC time and a random suffix).
        bag_path: where a recorder records this node's runs, reported in the learn result ("" = the
            recorder's, as its host names it).
        air_feature_low: lowest feature of the free-movement (track) trajectories (feature units; paper:
            0.2).
        air_feature_high: highest feature of the free-movement (track) trajectories (feature units; paper:
            0.8).
        rig_timeout_s: how long a goal waits for the rig's action and service (and the recorder) (s).
        rig_silence_s: a playing sequence whose rig sends no feedback for this long is abandoned as lost
            (s); the rig sends feedback every 0.2 s.
        rig_lost_limit_s: how long a run waits for a lost rig to answer again before it ends (s); the
            lost sequence is then played again from rest.
        rig_reset_timeout_s: longest wait for the rig's reset (s; at most rig_lost_limit_s).
        recorder_node: name of the recorder node in this namespace: every goal first waits until it
            subscribes to the rig's sample topics, so the recorded run is whole ("" = do not wait).
        learner: babbling, preprocessing and inverse-map settings.
        cycle: limit-cycle shape, timing and treadmill feature bounds (also the search's bounds).
        search: reward search (threshold, attempt budgets, sigma schedule).
    """

    run_id: str = ""
    bag_path: str = ""
    air_feature_low: float = AIR_FEATURE_BOUNDS[0]
    air_feature_high: float = AIR_FEATURE_BOUNDS[1]
    rig_timeout_s: float = 30.0
    rig_silence_s: float = 2.0
    rig_lost_limit_s: float = 60.0
    rig_reset_timeout_s: float = 30.0
    recorder_node: str = ""
    learner: LearnerConfig = field(default_factory=LearnerConfig)
    cycle: LimitCycleConfig = field(default_factory=LimitCycleConfig)
    search: SearchConfig = field(default_factory=SearchConfig)

    def __post_init__(self) -> None:
        require(
            0.0 < self.air_feature_low < self.air_feature_high,
            "air_feature_low, air_feature_high",
            f"must satisfy 0 < low < high, got ({self.air_feature_low}, {self.air_feature_high})",
        )
        for name in ("rig_timeout_s", "rig_silence_s", "rig_lost_limit_s", "rig_reset_timeout_s"):
            require_positive(getattr(self, name), name)

    @property
    def air_cycle(self) -> LimitCycleConfig:
        """The limit cycles of the free-movement experiments: the treadmill's, with the air bounds."""
        return replace(self.cycle, feature_low=self.air_feature_low, feature_high=self.air_feature_high)

    @property
    def search_config(self) -> SearchConfig:
        """The search, with the cycle's feature count and bounds."""
        return replace(
            self.search,
            n_features=self.cycle.n_spokes,
            feature_low=self.cycle.feature_low,
            feature_high=self.cycle.feature_high,
        )


@dataclass(frozen=True)
class _Step:
    """The next attempt of an experiment, as its attempt_start event announces it."""

    phase: str
    number: int
    features: np.ndarray | None = None


class LearnerNode(Node):
    """Hosts the babble, attempt, learn and track actions; one goal at a time."""

    def __init__(self, parameter_overrides: list[Parameter] | None = None) -> None:
        super().__init__("learner", namespace=DEFAULT_NAMESPACE, parameter_overrides=parameter_overrides)
        search_fields = ("n_features", "feature_low", "feature_high")
        base = declare_config(self, LearnerNodeConfig, exclude=("learner", "cycle", "search"))
        self.config = replace(
            base,
            learner=declare_config(self, LearnerConfig, "learner."),
            cycle=declare_config(self, LimitCycleConfig, "cycle."),
            search=declare_config(self, SearchConfig, "search.", exclude=search_fields),
        )
        cfg = self.config
        # A reset waited for while the rig is lost must not outlast the limit (it blocks until answered).
        reset_timeout_s = min(cfg.rig_reset_timeout_s, cfg.rig_lost_limit_s)
        self.client = RigClient(self, cfg.rig_timeout_s, cfg.rig_silence_s, reset_timeout_s)
        self.rig = RetryingRig(self.client, cfg.rig_lost_limit_s, on_event=self._rig_event)
        self.watches = list(self.client.watches)
        self.recorder = RecorderLink(self, cfg.recorder_node) if cfg.recorder_node else None
        if self.recorder is not None:
            self.watches.append(self.recorder.watch)
        self.learner = Learner(cfg.learner)
        self.run_id = cfg.run_id or new_run_id(datetime.now(timezone.utc), np.random.default_rng())
        self.bag_path = cfg.bag_path
        self._busy = False
        self._busy_lock = threading.Lock()
        self._cancel = threading.Event()

        self.record = RunPublisher(self, lambda: self.run_id)
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

    def _adopt_recorder_run(self) -> None:
        """With no run id of its own, the learner's runs are the recorder's: its id and its bag."""
        recorded = self.recorder.run() if self.recorder is not None else None
        if recorded is None or self.config.run_id:
            return
        run_id, bag = recorded
        self.run_id = run_id or self.run_id
        self.bag_path = self.config.bag_path or bag

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

    @property
    def _control(self) -> str:
        return self.learner.config.control.value

    def _resume_hint(self) -> str:
        where = self.bag_path or "bags/<run>"
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
        goals.check_attempt(goal, self.config.cycle, self.learner)

    def _check_track(self, goal: Track.Goal) -> None:
        goals.check_track(goal, self.config.air_cycle, self.learner)

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
                self._adopt_recorder_run()
                return execute(goal_handle)
            except (RigCancelled, FitCancelled) as err:
                self.record.event(Event.RUN_END, detail={run_events.CANCELLED: str(err)})
                goal_handle.canceled()
                return action.Result(message=f"cancelled: {err}")
            except RigUnreachable as err:
                message = f"{err}; {self._resume_hint()}" if action is Learn else str(err)
                self.get_logger().error(f"{action.__name__} goal aborted: {message}")
                self.record.event(
                    Event.RUN_END, detail={run_events.ERROR: str(err), run_events.RESUME: self.bag_path}
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

        fit = self._babble(goal_handle.request.duration_s or None, progress)
        goal_handle.succeed()
        return Babble.Result(sample_count=len(self.learner.dataset), validation_rmse=fit.validation_rmse)

    def _babble(self, duration_s: float | None, progress: Callable[[int, int], None]) -> FitReport:
        fit = self.learner.babble(_BabblingSegments(self), duration_s, progress, self._cancel)
        self.record.inverse_map(self.learner, fit)
        return fit

    def _execute_attempt(self, goal_handle: ServerGoalHandle) -> Attempt.Result:
        goal = goal_handle.request
        cycle = replace(self.config.cycle, n_cycles=goal.cycles) if goal.cycles else self.config.cycle
        features = np.asarray(goal.features)
        number = self.learner.refinements + 1
        self.record.attempt_start("attempt", number, features, cycle, self._control)

        def progress(done: int, total: int) -> None:
            goal_handle.publish_feedback(
                Attempt.Feedback(stage="playing", ticks_done=done, ticks_total=total)
            )

        refine = not goal.skip_refinement
        outcome, fit = self.learner.attempt(self.rig, features, cycle, refine, progress, self._cancel)
        self.record.attempt_end("attempt", number, outcome)
        if fit is not None:
            self.record.inverse_map(self.learner, fit)
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
        if goal.resume_bag:
            run, fit = self._resume(goal.resume_bag), None
        else:
            run, fit = self._start_run(goal_handle)
        self._checkpoint(run)

        def attempt_done(report: AttemptReport) -> None:
            self.record.attempt_end(
                report.phase.value,
                report.number,
                report.outcome,
                sigma=report.sigma,
                best=report.best_reward_mm,
            )
            self._checkpoint(run)
            goal_handle.publish_feedback(
                Learn.Feedback(
                    phase=report.phase.value,
                    babbling_progress=1.0,
                    attempt=report.number,
                    reward_mm=report.outcome.reward_mm,
                    best_reward_mm=report.best_reward_mm,
                    sigma=report.sigma or 0.0,
                )
            )

        self._run_steps(
            goal_handle,
            run,
            lambda: _Step(run.search.phase.value, len(run.search.history) + 1, run.next_features()),
            attempt_done,
        )
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
            run_id=self.run_id,
            bag_path=self.bag_path,
        )

    def _start_run(self, goal_handle: ServerGoalHandle) -> tuple[TreadmillRun, FitReport]:
        """A new run: babble (or fit on a recorded run's data), then the search from its start."""
        goal = goal_handle.request
        search = self.config.search_config
        search = replace(
            search,
            threshold_mm=goal.threshold_mm or search.threshold_mm,
            max_exploration_attempts=goal.max_exploration_attempts or search.max_exploration_attempts,
            exploitation_attempts=goal.exploitation_attempts or search.exploitation_attempts,
        )
        self.record.event(
            Event.RUN_START,
            detail={
                "goal": {"dataset_bag": goal.dataset_bag, "babbling_duration_s": goal.babbling_duration_s},
                run_events.SEARCH: config_as_dict(search),
            },
        )
        if goal.dataset_bag:
            fit = self._fit_from_bag(goal.dataset_bag)
        else:

            def progress(done: int, total: int) -> None:
                goal_handle.publish_feedback(
                    Learn.Feedback(
                        phase="babbling",
                        babbling_progress=done / total,
                        reward_mm=math.nan,
                        best_reward_mm=math.nan,
                    )
                )

            fit = self._babble(goal.babbling_duration_s or None, progress)
        return TreadmillRun(self.learner, search, self.config.cycle, self.config.learner.seed), fit

    def _resume(self, bag: str) -> TreadmillRun:
        """The run recorded in `bag`, restored at its last checkpoint; the continuation keeps its id.

        Raises:
            ValueError: the bag holds no run to continue, or this node's learner and cycle settings are not
                the recorded run's (the search's come from the bag).
        """
        from g2p.bags.resume import resume_run  # only runs reading a bag need the bag library

        mine = json.loads(json.dumps(config_as_dict(self.config)))  # as recorded: JSON types
        point, run = resume_run(
            bag, mine, self.config.learner, self.config.cycle, self.resolve_topic_name("~/config")
        )
        self.learner = run.learner
        self.run_id = point.run_id
        self.record.event(
            Event.RUN_START,
            detail={
                run_events.SEARCH: point.search,
                "resumed_from": {"bag": str(point.bag), "attempt": point.checkpoint.attempt},
            },
        )
        self.record.inverse_map(self.learner, None)
        self.get_logger().info(
            f"run {self.run_id} resumed from {bag} after attempt {point.checkpoint.attempt} "
            f"({run.search.phase.value}, best {run.search.best_reward_mm:.1f} mm)"
        )
        return run

    def _checkpoint(self, run: TreadmillRun) -> None:
        """Record the run's state (g2p.checkpoint): `learn --resume` continues from the last one."""
        checkpoint = capture(run)
        self.record.event(
            Event.CHECKPOINT,
            attempt=checkpoint.attempt,
            detail={run_events.CHECKPOINT: json.loads(checkpoint.to_json())},
        )

    def _fit_from_bag(self, bag: str) -> FitReport:
        from g2p.bags.dataset import load_training_data  # only runs reading a bag need the bag library

        data = load_training_data(bag)
        fit = self.learner.fit_babbling(list(data.babbling))
        self.record.inverse_map(self.learner, fit)
        for k, recording in enumerate(data.attempts, start=1):
            fit = self.learner.refine_with(recording, f"attempt {k} from {bag}")
            self.record.inverse_map(self.learner, fit)
        self.record.event(
            Event.PHASE_END,
            phase="babbling",
            detail={"dataset_bag": bag, "samples": len(self.learner.dataset)},
        )
        return fit

    def _execute_track(self, goal_handle: ServerGoalHandle) -> Track.Result:
        goal = goal_handle.request
        cycle = self.config.air_cycle
        rng = seed_streams(self.config.learner.seed).tracking
        experiment: TrajectoryRefinement | Generalization
        if goal.mode == Track.Goal.MODE_REFINE_ONE:
            features = np.asarray(goal.features) if len(goal.features) else random_features(rng, cycle, 1)[0]
            experiment = TrajectoryRefinement(self.learner, features, cycle, goal.refinements or 5)
        else:
            train = random_features(rng, cycle, goal.train_trajectories or 30)
            test = random_features(rng, cycle, goal.test_trajectories or 30)
            experiment = Generalization(self.learner, cycle, train, test)

        def upcoming() -> _Step | None:
            """A training attempt is announced and recorded as one; the test tracking is not."""
            if isinstance(experiment, Generalization):
                if experiment.stage != "training":
                    return None
                return _Step("tracking", experiment.trained + 1, experiment.train[experiment.trained])
            return _Step("tracking", len(experiment.outcomes) + 1, experiment.features)

        def step_done(report: TrackingReport) -> None:
            if report.outcome is not None:
                self.record.attempt_end("tracking", report.number, report.outcome)
            goal_handle.publish_feedback(
                Track.Feedback(
                    stage=report.stage, index=report.number, tracking_mse_deg2=report.tracking.mse_deg2
                )
            )

        self._run_steps(goal_handle, experiment, upcoming, step_done)
        goal_handle.succeed()
        if isinstance(experiment, TrajectoryRefinement):
            return Track.Result(attempt_mse_deg2=[o.tracking.mse_deg2 for o in experiment.outcomes])
        result = experiment.result()
        return Track.Result(
            babbling_map_mse_deg2=[e.mse_deg2 for e in result.babbling_map],
            refined_map_mse_deg2=[e.mse_deg2 for e in result.refined_map],
        )

    def _run_steps(
        self,
        goal_handle: ServerGoalHandle,
        experiment: Experiment,
        upcoming: Callable[[], _Step | None],
        done: Callable[[Any], None],
    ) -> None:
        """Step `experiment` to its end: check cancel, announce the attempt, play it, report, publish the map.

        `upcoming` describes the next step (None: not an attempt of the run, e.g. a test trajectory, and
        not announced); `done` emits the step's end event and the goal's feedback.
        """
        while not experiment.finished:
            self._check_cancel(goal_handle)
            step = upcoming()
            if step is not None:
                self.record.attempt_start(
                    step.phase, step.number, step.features, experiment.cycle, self._control
                )
            report = experiment.next_attempt(self.rig, cancel=self._cancel)
            done(report)
            if report.fit is not None:
                self.record.inverse_map(self.learner, report.fit)


class _BabblingSegments:
    """The learner's rig while babbling: each sequence played is announced as a babbling segment.

    The events bound each segment's ticks in the recorded topics, so a map rebuilt from the bag sees
    the same segments the learner saw.
    """

    def __init__(self, node: LearnerNode) -> None:
        self._node = node

    def reset(self) -> None:
        self._node.rig.reset()

    def play(
        self,
        activations: np.ndarray,
        progress: ProgressCallback | None = None,
        cancel: threading.Event | None = None,
    ) -> Recording:
        self._node.record.segment(Event.PHASE_START)
        recording = self._node.rig.play(activations, progress, cancel)
        self._node.record.segment(Event.PHASE_END, recording)
        return recording
