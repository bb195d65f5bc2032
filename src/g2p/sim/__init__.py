"""The ROS-free MuJoCo simulation of the rig: a `g2p.plant.Plant` standing in for the physical leg.

    from g2p.sim import MujocoLeg, MujocoLegConfig, AIR_CARRIAGE_HEIGHT_M
    plant = MujocoLeg(MujocoLegConfig(carriage_height_m=AIR_CARRIAGE_HEIGHT_M))

The model is the MJCF file g2p/description/models/leg.xml; docs/SIMULATOR.md describes it.

May import: g2p.description.
"""

from g2p.sim.config import (
    AIR_CARRIAGE_HEIGHT_M,
    TREADMILL_CARRIAGE_HEIGHT_M,
    MujocoLegConfig,
    packaged_model_path,
)
from g2p.sim.leg import MujocoLeg, SimulationError
from g2p.sim.model import LegModel, ModelError, load_leg_model
from g2p.sim.motor import MotorConstants, electrical_power_w
from g2p.sim.sensors import TickClock, encoder_step_rad, quantize_angle
from g2p.sim.workspace import LIMIT_CYCLE_WORKSPACE, JointWorkspace

__all__ = [
    "AIR_CARRIAGE_HEIGHT_M",
    "LIMIT_CYCLE_WORKSPACE",
    "TREADMILL_CARRIAGE_HEIGHT_M",
    "JointWorkspace",
    "LegModel",
    "ModelError",
    "MotorConstants",
    "MujocoLeg",
    "MujocoLegConfig",
    "SimulationError",
    "TickClock",
    "electrical_power_w",
    "encoder_step_rad",
    "load_leg_model",
    "packaged_model_path",
    "quantize_angle",
]
