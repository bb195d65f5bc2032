"""The adversary: command sequences searched for what breaks the simulated leg through a rig's envelope.

- `patterns`: the spaces searched, periodic patterns (period, phase, duty, level, rise per motor) and
  free step sequences, and the plain square waves, as activation sequences.
- `harm`: a simulated leg that keeps what its physics saw each tick (sub-step tension peaks, cable paid
  into slack tendons), and the harm of a sequence played through a rig's tick loop and envelope, or
  through the Gymnasium environment as the RL baselines run it: stop entry speeds, tension peaks, slack
  payout, the trip.
- `search`: a black-box search (CMA-ES with restarts, the `cma` package) over a space for the most harm,
  and the replay of a sequence on many leg seeds.

The envelope (g2p.rig.envelope) is what it attacks; benchmarks/bench_adversary.py runs it.

May import: g2p.rig, g2p.sim, g2p.rl.
"""
