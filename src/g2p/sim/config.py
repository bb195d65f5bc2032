"""Configuration of the simulated rig: what a user changes without editing the MJCF model."""

from __future__ import annotations

import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from g2p.plant import NOMINAL_TICK_HZ
from g2p.safety import BASELINE_ACTIVATION
from g2p.sim.calibration import CalibrationError, LegCalibration
from g2p.validation import ConfigError, require, require_positive

# Height of the hip axis above the belt surface (m). The straight leg reaches 0.437 m below the hip
# (thigh 0.2 + shank 0.2 + ankle-to-sole 0.037), so at 0.42 m the extended leg presses 17 mm into the
# compliant belt span near vertical, while about 35 deg of knee flexion lifts the foot clear. Must equal the
# carriage height written in leg.xml (a test checks), so the viewer shows the default too.
TREADMILL_CARRIAGE_HEIGHT_M = 0.42
# Carriage raised so that no posture reaches the belt (the lowest reachable point is 0.437 m below the hip).
AIR_CARRIAGE_HEIGHT_M = 0.60


def packaged_model_path() -> Path:
    """Path of the MJCF model shipped with the package (g2p/description/models/leg.xml)."""
    return Path(str(resources.files("g2p.description").joinpath("models", "leg.xml")))


@dataclass(frozen=True)
class MujocoLegConfig:
    """Settings of the simulated rig; the physics itself lives in the MJCF model.

    Attributes:
        model_path: MJCF file of the leg; "" uses the packaged `g2p/description/models/leg.xml`. A custom
            model must keep the element names of the packaged one (joints, tendons, actuators, custom
            numerics).
        carriage_height_m: height of the hip axis above the belt surface (m). TREADMILL_CARRIAGE_HEIGHT_M
            puts the foot on the belt, AIR_CARRIAGE_HEIGHT_M keeps it in the air.
        calibration: the leg's physical parameters that differ from the model's (g2p.sim.calibration): a
            calibration YAML file (as `g2p-calibrate` writes it), or the name of a packaged one ("paper":
            the paper-like rig, docs/SIMULATOR.md); "" runs the model as it is.
        tick_hz: nominal rig tick rate (Hz); the rig ran at about 78 Hz.
        tick_jitter_s: half-width of the uniform jitter added to each tick period (s); each period is
            1/tick_hz + U(-tick_jitter_s, +tick_jitter_s). 0.0008 s reproduces the measured 78 +/- 5 Hz.
        substeps: physics steps per tick (the timestep is the tick period divided by this). 8 keeps the
            joint-limit overshoot under about 2.5 deg when babbling slams the joints into their stops.
        encoder_bits: resolution of the absolute joint encoders (bits per turn).
        baseline_activation: the activation always applied, whatever the command (dimensionless).
        settle_s: simulated time at baseline activation used once, at construction, to find the resting
            posture every attempt starts from (s).
        seed: seed of the tick-jitter generator when the plant is not given one.
    """

    model_path: str = ""
    carriage_height_m: float = TREADMILL_CARRIAGE_HEIGHT_M
    calibration: str = ""
    tick_hz: float = NOMINAL_TICK_HZ
    tick_jitter_s: float = 0.0008
    substeps: int = 8
    encoder_bits: int = 14
    baseline_activation: float = BASELINE_ACTIVATION
    settle_s: float = 2.0
    seed: int = 0

    def __post_init__(self) -> None:
        if self.model_path:
            require(Path(self.model_path).is_file(), "model_path", f"no such file: {self.model_path!r}")
        require_positive(self.carriage_height_m, "carriage_height_m")
        if self.calibration:
            try:
                LegCalibration.load(self.calibration)
            except CalibrationError as err:
                raise ConfigError(f"calibration: {err}") from err
        require_positive(self.tick_hz, "tick_hz")
        require(
            math.isfinite(self.tick_jitter_s) and 0.0 <= self.tick_jitter_s < 0.5 / self.tick_hz,
            "tick_jitter_s",
            f"must be in [0, half the tick period), got {self.tick_jitter_s!r}",
        )
        require(
            isinstance(self.substeps, int) and 1 <= self.substeps <= 100,
            "substeps",
            f"must be an integer in [1, 100], got {self.substeps!r}",
        )
        require(
            isinstance(self.encoder_bits, int) and 1 <= self.encoder_bits <= 32,
            "encoder_bits",
            f"must be an integer in [1, 32], got {self.encoder_bits!r}",
        )
        require(
            math.isfinite(self.baseline_activation) and 0.0 <= self.baseline_activation < 1.0,
            "baseline_activation",
            f"must be in [0, 1), got {self.baseline_activation!r}",
        )
        require(
            math.isfinite(self.settle_s) and self.settle_s >= 0.0,
            "settle_s",
            f"must be a finite number >= 0, got {self.settle_s!r}",
        )
        require(
            isinstance(self.seed, int) and self.seed >= 0,
            "seed",
            f"must be an integer >= 0, got {self.seed!r}",
        )

    @property
    def resolved_model_path(self) -> Path:
        """The MJCF file this configuration loads."""
        return Path(self.model_path) if self.model_path else packaged_model_path()

    @property
    def leg_calibration(self) -> LegCalibration:
        """The calibration this configuration names (an empty one when none)."""
        return LegCalibration.load(self.calibration) if self.calibration else LegCalibration(parameters={})

    @property
    def nominal_period_s(self) -> float:
        """Nominal tick period 1/tick_hz (s)."""
        return 1.0 / self.tick_hz


__all__ = [
    "AIR_CARRIAGE_HEIGHT_M",
    "TREADMILL_CARRIAGE_HEIGHT_M",
    "ConfigError",
    "MujocoLegConfig",
    "packaged_model_path",
]
