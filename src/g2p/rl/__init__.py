"""G2P against model-free RL: Gymnasium environments of the rig, the baselines, and sweeps over seeds.

- `envs`: the Gymnasium environments (`g2p/Treadmill-v0`, `g2p/Track-v0`) over any plant.
- `baselines`: every method's learning curve in rig time, the rig as it runs (G2P, PPO, SAC, TQC, random
  patterns).
- `sweep`: seeds x variants x methods on Ray, here or on a cluster.

May import: g2p.inverse_map, g2p.rig, g2p.sim, g2p.learning.
"""
