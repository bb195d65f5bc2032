"""The adversary: periodic patterns searched for what breaks the simulated leg through a rig's envelope.

- `patterns`: a periodic open-loop pattern per motor (period, phase, duty, level, rise) and the plain
  square waves, as activation sequences.
- `harm`: a simulated leg that keeps what its physics saw each tick (sub-step tension peaks, cable paid
  into slack tendons), and the harm of a pattern played through a rig's tick loop and envelope: stop
  entry speeds, tension peaks, slack payout, the trip.
- `search`: a black-box search (scipy's differential evolution) over patterns for the most harm, and the
  replay of a pattern on many leg seeds.

The envelope (g2p.rig.envelope) is what it attacks; benchmarks/bench_adversary.py runs it.

May import: g2p.rig, g2p.sim.
"""
