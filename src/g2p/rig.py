"""The rig as the learner sees it: reset to rest, play a whole activation sequence, get its samples.

The learner drives a `Rig`: an in-process plant wrapped by `PlantRig`, or the ROS 2 rig contract
(g2p_ros.rig_client.RigClient) served by the simulator or the hardware driver.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from g2p.plant import NOMINAL_TICK_HZ, Plant, Recording
from g2p.safety import check_activation_sequence

ProgressCallback = Callable[[int, int], None]

# The rig contract's default namespace: its topics, services and actions live under it.
DEFAULT_NAMESPACE = "/leg"


class RigError(RuntimeError):
    """The rig could not play a sequence or reset."""


class RigCancelled(RigError):
    """A sequence was cancelled on request; the rig dropped to baseline."""


class Rig(Protocol):
    """Sequence-level access to a leg on a treadmill."""

    def reset(self) -> None:
        """Return to the resting posture every attempt starts from."""
        ...

    def play(
        self,
        activations: NDArray[np.float64],
        progress: ProgressCallback | None = None,
        cancel: threading.Event | None = None,
    ) -> Recording:
        """Play activations (N, 3) one row per tick and return the N recorded ticks.

        Raises:
            RigError: the sequence could not be played whole.
            RigCancelled: `cancel` was set before the end.
        """
        ...


class PlantRig:
    """A `Rig` over an in-process plant (no ROS): for fast experiments and tests.

    Args:
        plant: the plant to drive.
        progress_every: ticks between progress callbacks.
    """

    def __init__(self, plant: Plant, progress_every: int = round(NOMINAL_TICK_HZ)) -> None:
        self.plant = plant
        self._progress_every = progress_every

    def reset(self) -> None:
        """Reset the plant to rest."""
        self.plant.reset()

    def play(
        self,
        activations: NDArray[np.float64],
        progress: ProgressCallback | None = None,
        cancel: threading.Event | None = None,
    ) -> Recording:
        """Play the sequence on the plant, tick by tick."""
        seq = check_activation_sequence(activations)
        samples = []
        for k, row in enumerate(seq):
            if cancel is not None and cancel.is_set():
                self.plant.step(np.zeros(3))  # one tick at baseline, as the ROS rig does on cancel
                raise RigCancelled(f"sequence cancelled after {k} of {len(seq)} ticks")
            samples.append(self.plant.step(row))
            if progress is not None and (k + 1) % self._progress_every == 0:
                progress(k + 1, len(seq))
        if progress is not None:
            progress(len(seq), len(seq))
        return Recording.from_samples(samples)
