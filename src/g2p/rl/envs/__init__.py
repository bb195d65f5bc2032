"""Gymnasium environments of the rig (extra `rl`), registered on import.

    import gymnasium as gym
    import g2p.rl.envs
    env = gym.make("g2p/Treadmill-v0")             # the simulated rig; frame_skip=4, energy_cost_weight=...
    env = gym.make("g2p/Track-v0", features=f)     # follow the limit cycle of features f, in the air

Over the ROS 2 rig contract (the simulator node or the hardware), pass the plant:
`gym.make("g2p/Treadmill-v0", plant=TickPlant(node), reset_noise_scale=0)` (g2p_ros.tick_plant).
docs/RL.md describes both and their timing limits.
"""

import gymnasium as gym

from g2p.rl.envs.leg_env import RIG_OBSERVATION, LegEnv
from g2p.rl.envs.track import TrackEnv
from g2p.rl.envs.treadmill import TreadmillEnv

TREADMILL_ID = "g2p/Treadmill-v0"
TRACK_ID = "g2p/Track-v0"

# Episodes truncate by themselves after the episode's ticks (LegEnv.episode_ticks), so no TimeLimit.
if TREADMILL_ID not in gym.registry:
    gym.register(TREADMILL_ID, entry_point="g2p.rl.envs.treadmill:TreadmillEnv")
if TRACK_ID not in gym.registry:
    gym.register(TRACK_ID, entry_point="g2p.rl.envs.track:TrackEnv")

__all__ = ["RIG_OBSERVATION", "TRACK_ID", "TREADMILL_ID", "LegEnv", "TrackEnv", "TreadmillEnv"]
