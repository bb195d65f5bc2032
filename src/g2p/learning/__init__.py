"""The G2P learning algorithm over any `g2p.rig.Rig`: from babbling to a gait, and the run's record.

- `babbling`: the motor babbling activations. `kinematics`: differentiation and training pairs.
- `limit_cycle`: the 10-number limit-cycle features and their joint kinematics.
- `search`: the two-phase reward search (ask/tell). `attempt`: one attempt played and scored.
- `learner`: babble, fit and refine the inverse map. `experiments`: the treadmill run and tracking tasks.
- `seeds`: a run's seed expanded into its random streams. `checkpoint`: resume a run where it stopped.
- `run_events`: the events a run emits (recorded and shown live).

May import: g2p.inverse_map, g2p.rig.
"""
