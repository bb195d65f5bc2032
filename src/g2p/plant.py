"""The plant interface shared by the MuJoCo simulation and the physical rig, and its sample types.

A plant is the leg with its motors, sensors and treadmill. It is driven one rig tick (about 78 Hz) at a
time: `step` applies three motor activations for one tick and returns what the sensors read at the end
of it. `reset` returns the leg to the resting posture every attempt starts from.

Conventions (the rig contract, see g2p_interfaces):
    joints: index 0 = proximal (hip), 1 = distal (knee); angles in rad, positive = counter-clockwise
        seen with the leg facing +x and z up; 0, 0 = leg hanging straight down.
    motors: index 0, 1, 2 = M0, M1, M2; activations dimensionless in [0, 1].
    belt: displacement in mm, cumulative since the plant was created, positive when the foot pushes the
        belt backward (forward locomotion).

Also the motors' first-order thermal model, which the simulated windings and the rig's envelope share.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from g2p.safety import BASELINE_ACTIVATION, check_activation_sequence

FloatArray = NDArray[np.float64]

N_JOINTS = 2
N_MOTORS = 3
JOINT_NAMES = ("proximal", "distal")
MOTOR_NAMES = ("M0", "M1", "M2")
NOMINAL_TICK_HZ = 78.0

# Columns of the per-tick vector fields of TickSample and Recording; scalar fields have none.
_WIDTHS = {
    "activation": N_MOTORS,
    "position_rad": N_JOINTS,
    "velocity_rad_s": N_JOINTS,
    "current_a": N_MOTORS,
    "power_w": N_MOTORS,
    "energy_j": N_MOTORS,
}


def stamp_ns(t_s: float) -> int:
    """A time in seconds as whole nanoseconds, as a ROS stamp carries it (rounded)."""
    return round(t_s * 1e9)


def on_stamp_grid(t_s: float) -> float:
    """`t_s` in whole nanoseconds, as a ROS stamp carries it, back in seconds (s).

    Every rig reports its ticks' times so (g2p.rig.tick_loop): in-process and over ROS, a learner gets the
    same floats.
    """
    return stamp_ns(t_s) * 1e-9


@dataclass(frozen=True)
class TickSample:
    """What the rig measured over one tick.

    Attributes:
        t_s: stamp of the end of the tick (s, plant clock: simulation time or monotonic time).
        activation: activations applied during the tick, shape (3,).
        position_rad: joint angles at the end of the tick, shape (2,).
        velocity_rad_s: joint angular velocities at the end of the tick, shape (2,).
        belt_mm: cumulative belt displacement at the end of the tick (mm, + backward).
        belt_velocity_mm_s: belt velocity at the end of the tick (mm/s, + backward).
        current_a: mean motor current over the tick, shape (3,) (A).
        power_w: mean electrical motor power over the tick, shape (3,) (W).
        energy_j: cumulative electrical energy since the plant was created, shape (3,) (J).
    """

    t_s: float
    activation: FloatArray
    position_rad: FloatArray
    velocity_rad_s: FloatArray
    belt_mm: float
    belt_velocity_mm_s: float
    current_a: FloatArray
    power_w: FloatArray
    energy_j: FloatArray


@dataclass(frozen=True)
class Recording:
    """Samples of consecutive ticks, as arrays with one row per tick (N ticks).

    Attributes:
        t_s: tick stamps, shape (N,) (s).
        activation: applied activations, shape (N, 3).
        position_rad: joint angles, shape (N, 2).
        velocity_rad_s: joint velocities, shape (N, 2).
        belt_mm: cumulative belt displacement, shape (N,) (mm).
        belt_velocity_mm_s: belt velocity, shape (N,) (mm/s).
        current_a: mean motor currents, shape (N, 3) (A).
        power_w: mean electrical motor power, shape (N, 3) (W).
        energy_j: cumulative energy, shape (N, 3) (J).
    """

    t_s: FloatArray
    activation: FloatArray
    position_rad: FloatArray
    velocity_rad_s: FloatArray
    belt_mm: FloatArray
    belt_velocity_mm_s: FloatArray
    current_a: FloatArray
    power_w: FloatArray
    energy_j: FloatArray

    def __post_init__(self) -> None:
        n = len(self.t_s)
        for f in fields(self):
            shape = np.shape(getattr(self, f.name))
            expected = (n, _WIDTHS[f.name]) if f.name in _WIDTHS else (n,)
            if shape != expected:
                raise ValueError(f"Recording.{f.name}: expected shape {expected}, got {shape}")

    def __len__(self) -> int:
        return len(self.t_s)

    @classmethod
    def from_samples(cls, samples: Sequence[TickSample]) -> Recording:
        """Stack tick samples into arrays."""
        return cls(
            **{
                f.name: np.array([getattr(s, f.name) for s in samples], dtype=np.float64).reshape(
                    len(samples), *([_WIDTHS[f.name]] if f.name in _WIDTHS else [])
                )
                for f in fields(TickSample)
            }
        )

    @classmethod
    def empty(cls) -> Recording:
        """A recording of zero ticks."""
        return cls.from_samples([])

    def slice(self, start: int | None = None, stop: int | None = None) -> Recording:
        """The ticks [start, stop) as a new recording."""
        return Recording(**{f.name: getattr(self, f.name)[start:stop] for f in fields(self)})

    def take(self, index: NDArray[np.intp]) -> Recording:
        """The ticks at `index` (shape (M,), tick numbers in order) as a new recording."""
        return Recording(**{f.name: getattr(self, f.name)[index] for f in fields(self)})

    def sample(self, k: int) -> TickSample:
        """Tick `k` as a sample."""
        return TickSample(**{f.name: getattr(self, f.name)[k] for f in fields(self)})

    @property
    def belt_travel_mm(self) -> float:
        """Belt displacement from the end of the first tick to the end of the last (mm, + backward)."""
        return float(self.belt_mm[-1] - self.belt_mm[0]) if len(self) else 0.0

    @property
    def energy_used_j(self) -> float:
        """Energy drawn by all motors from the end of the first tick to the end of the last (J)."""
        return float(np.sum(self.energy_j[-1] - self.energy_j[0])) if len(self) else 0.0


def concatenate(recordings: Sequence[Recording]) -> Recording:
    """Join recordings end to end (stamps are kept as they are)."""
    if not recordings:
        return Recording.empty()
    return Recording(
        **{f.name: np.concatenate([getattr(r, f.name) for r in recordings]) for f in fields(Recording)}
    )


@runtime_checkable
class Plant(Protocol):
    """A tendon-driven leg on a treadmill, simulated or physical, driven one tick at a time."""

    @property
    def tick_hz(self) -> float:
        """Nominal tick rate (Hz)."""
        ...

    def reset(self) -> TickSample:
        """Return to the resting posture (motors at baseline) and return a sample taken at rest."""
        ...

    def step(self, activation: FloatArray) -> TickSample:
        """Apply activations for one tick and return the tick's sample.

        Args:
            activation: shape (3,), finite, in [0, 1]. The plant applies at least the baseline tension.

        Raises:
            ValueError: the activation is not 3 finite numbers.
        """
        ...

    def close(self) -> None:
        """Release the plant's resources, leaving motors at baseline or off."""
        ...


def hold(plant: Plant, activation: tuple[float, float, float] | FloatArray, ticks: int) -> Recording:
    """Play one activation (3,) for `ticks` ticks; returns their samples (see `run_sequence`)."""
    return run_sequence(plant, np.tile(np.asarray(activation, dtype=np.float64), (ticks, 1)))


def run_sequence(plant: Plant, activations: FloatArray) -> Recording:
    """Play an activation sequence on a plant, one row per tick.

    Args:
        plant: the plant, in whatever state it is (call `reset` first for a fresh attempt).
        activations: shape (N, 3), finite, in [0, 1].

    Returns:
        The N ticks' samples.

    Raises:
        ValueError: the sequence has the wrong shape or non-finite values (nothing is played).
    """
    seq = check_activation_sequence(activations)
    return Recording.from_samples([plant.step(row) for row in seq])


def first_order_temperature(
    temperature_c: FloatArray,
    heat_w: FloatArray,
    dt_s: float,
    thermal_resistance_k_per_w: float,
    time_constant_s: float,
    ambient_c: float,
) -> FloatArray:
    """Temperatures after `dt_s` of constant heat: the exact solution of a first-order thermal model.

    C dT/dt = P - (T - T_ambient) / R_th with C = tau / R_th: T relaxes toward T_ambient + P R_th with
    time constant tau.

    Args:
        temperature_c: the temperatures now, any shape (deg C).
        heat_w: the heat put in over the interval, same shape (W).
        dt_s: the interval (s).
        thermal_resistance_k_per_w: R_th to ambient (K/W).
        time_constant_s: tau (s).
        ambient_c: the ambient temperature (deg C).
    """
    target = ambient_c + heat_w * thermal_resistance_k_per_w
    result: FloatArray = target + (temperature_c - target) * math.exp(-dt_s / time_constant_s)
    return result


__all__ = [
    "BASELINE_ACTIVATION",
    "JOINT_NAMES",
    "MOTOR_NAMES",
    "NOMINAL_TICK_HZ",
    "N_JOINTS",
    "N_MOTORS",
    "Plant",
    "Recording",
    "TickSample",
    "concatenate",
    "first_order_temperature",
    "hold",
    "on_stamp_grid",
    "run_sequence",
    "stamp_ns",
]
