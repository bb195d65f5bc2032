"""The main job's learning run in-process, without ROS: `run_treadmill` on the MuJoCo leg, the defaults.

    scripts/with-env python benchmarks/treadmill_in_process.py

`bench_graph.py` runs this script as the in-process side of the graph's overhead: its process's wall time
against `bringup`'s, and the `run_treadmill` call's against the learning run through the graph. Prints the
call's wall time (s), the attempts and the best reward (mm) as JSON. Imports only the core, as a
user's script would.
"""

from __future__ import annotations

import json
import time

import g2p.inverse_map.training  # noqa: F401  (torch: imported by the first fit otherwise, inside the call)
from g2p.learning.experiments import run_treadmill
from g2p.learning.learner import Learner, LearnerConfig
from g2p.learning.limit_cycle import LimitCycleConfig
from g2p.learning.search import SearchConfig
from g2p.rig import PlantRig
from g2p.sim import MujocoLeg, MujocoLegConfig


def main() -> None:
    """Run once and print {"run_s": ..., "attempts": ..., "best_reward_mm": ...}."""
    learner, rig = Learner(LearnerConfig()), PlantRig(MujocoLeg(MujocoLegConfig()))  # before the graph's run
    t0 = time.perf_counter()
    run = run_treadmill(learner, rig, SearchConfig(), LimitCycleConfig())
    run_s = time.perf_counter() - t0
    attempts = run.exploration_attempts + run.exploitation_attempts
    print(
        json.dumps({"run_s": run_s, "attempts": attempts, "best_reward_mm": run.best_reward_mm}), flush=True
    )


if __name__ == "__main__":
    main()
