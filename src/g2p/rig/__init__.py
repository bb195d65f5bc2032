"""The rig runtime: the one tick loop every rig runs, the limits it enforces, and the rig as a client sees it.

- `rigs`: the `Rig` protocol (reset, play a sequence or a trajectory), `PlantRig` over an in-process plant,
  `RetryingRig`, and the rig's errors; re-exported here.
- `tick_loop`: the tick (choose the activation, apply the limits, step the plant), shared by the simulator
  node, the hardware driver and `PlantRig`.
- `envelope`: the safety envelope (soft joint limits, ramp, thermal budget) that the tick loop applies.
- `closed_loop`: the trajectory tracker, the inverse map evaluated on the rig every tick.
- `tendon_check`: does each tendon, pulled alone, turn the joints the documented way?

May import: g2p.description, g2p.inverse_map.
"""

from g2p.rig.rigs import (
    DEFAULT_NAMESPACE,
    PlantRig,
    ProgressCallback,
    RetryingRig,
    Rig,
    RigBusy,
    RigCancelled,
    RigError,
    RigUnreachable,
)

__all__ = [
    "DEFAULT_NAMESPACE",
    "PlantRig",
    "ProgressCallback",
    "RetryingRig",
    "Rig",
    "RigBusy",
    "RigCancelled",
    "RigError",
    "RigUnreachable",
]
