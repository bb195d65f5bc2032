"""The learner node's settings (its ROS parameters: g2p_ros.params.declare_config)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from g2p.learning.learner import LearnerConfig
from g2p.learning.limit_cycle import AIR_FEATURE_BOUNDS, LimitCycleConfig
from g2p.learning.search import SearchConfig
from g2p.validation import require, require_positive


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
