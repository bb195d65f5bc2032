"""System identification of the simulated rig from a recorded run (`g2p-calibrate`, extra `calibrate`).

    from g2p.identification import FitConfig, calibrate, load_recorded_run
    cal = calibrate(load_recorded_run("bags/<run>"), FitConfig())
    cal.calibration.to_yaml()   # what MujocoLegConfig(calibration=...) loads

docs/SIMULATOR.md ("Calibration") describes the method and its limits.

May import: g2p.description, g2p.inverse_map, g2p.rig, g2p.sim, g2p.learning, g2p.bags.
"""

from g2p.identification.calibrate import Calibration, calibrate
from g2p.identification.fit import DEFAULT_PARAMETERS, FitConfig, FitError, FitResult, fit, replay
from g2p.identification.segments import CalibrationInputError, RecordedRun, Segment, load_recorded_run

__all__ = [
    "DEFAULT_PARAMETERS",
    "Calibration",
    "CalibrationInputError",
    "FitConfig",
    "FitError",
    "FitResult",
    "RecordedRun",
    "Segment",
    "calibrate",
    "fit",
    "load_recorded_run",
    "replay",
]
