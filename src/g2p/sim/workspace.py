"""Where in the joint-angle plane the learner should centre its limit cycles on the simulated rig."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from g2p.plant import FloatArray


@dataclass(frozen=True)
class JointWorkspace:
    """A rectangle of the (proximal, distal) angle plane: centre +/- half range per joint.

    Attributes:
        centre_rad: centre of the cycles, (proximal, distal) (rad).
        half_range_rad: largest excursion from the centre a cycle should make, (proximal, distal) (rad), > 0.
    """

    centre_rad: tuple[float, float]
    half_range_rad: tuple[float, float]

    @property
    def stepping_radius_rad(self) -> tuple[float, float]:
        """Signed radii for g2p.learning.limit_cycle that run its cycles in the stepping direction (rad).

        There, point = centre + f * radius * (sin theta, cos theta), which runs clockwise in the
        (proximal, distal) plane when both radii are positive; stepping runs counter-clockwise, so the
        proximal radius is negative.
        """
        return (-self.half_range_rad[0], self.half_range_rad[1])

    def loop(self, radius: FloatArray, phase_rad: FloatArray) -> FloatArray:
        """Angles of points on a loop around the centre, traversed in the stepping direction.

        Point k is (centre_0 + half_0 * radius_k * cos(phase_k), centre_1 + half_1 * radius_k * sin(phase_k)).
        With the phase increasing, the loop is counter-clockwise in the (proximal, distal) plane: near the top
        (distal joint nearest straight, the foot on the belt) the proximal joint extends, sweeping the foot
        backward (stance); near the bottom (knee flexed, foot lifted) it flexes, bringing the foot forward
        (swing).

        Args:
            radius: relative spoke lengths, shape (N,) (1 reaches the half range).
            phase_rad: phases, shape (N,) (rad).

        Returns:
            Joint angles, shape (N, 2) (rad).
        """
        c = np.asarray(self.centre_rad, dtype=np.float64)
        h = np.asarray(self.half_range_rad, dtype=np.float64)
        r = np.asarray(radius, dtype=np.float64)
        p = np.asarray(phase_rad, dtype=np.float64)
        return np.stack([c[0] + h[0] * r * np.cos(p), c[1] + h[1] * r * np.sin(p)], axis=-1)


# The usable range of the simulated leg for stepping cycles: hip 0 +/- 0.6 rad (+/-34 deg, inside its
# +/-55 deg stops), knee -0.6 +/- 0.6 rad (-69 to 0 deg: the top of a full-size loop is the straight knee,
# which puts the foot on the belt near vertical; the bottom clears it). Chosen by running a stand-in G2P
# learner on the plant (docs/SIMULATOR.md): random loops in this rectangle touch the belt in stance and most
# push it backward.
LIMIT_CYCLE_WORKSPACE = JointWorkspace(centre_rad=(0.0, -0.6), half_range_rad=(0.6, 0.6))
