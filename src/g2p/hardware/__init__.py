"""The physical rig's I/O, ROS-free: chip drivers on injected buses, the wiring description, `HardwareLeg`.

    from g2p.hardware import HardwareLeg, load_wiring, open_devices
    rig = load_wiring("wiring.yaml")
    leg = HardwareLeg(open_devices(rig), rig)     # a g2p.plant.Plant; outputs off until reset()

Device classes take their bus object (spidev-, smbus2- or gpiod-like) as an argument; only
`g2p.hardware.devices.open_devices` imports spidev, smbus2 and gpiod, lazily. `g2p.hardware_fake.chips` has
chips that answer byte for byte, backed by the MuJoCo leg, for tests and benches without a Pi.
docs/DRIVER.md describes the wiring.

May import: nothing of g2p beyond the top-level modules (it is what the Pi installs).
"""

from g2p.hardware.as5048a import AS5048A, EncoderModel, MagnetStatus
from g2p.hardware.clock import Clock, MonotonicClock, SimulatedClock
from g2p.hardware.devices import BusFactory, LinuxBuses, RigDevices, build_devices, open_devices
from g2p.hardware.errors import (
    DeviceError,
    EncoderError,
    EncoderErrorFlag,
    EncoderParityError,
    HardwareError,
    HardwareFault,
)
from g2p.hardware.ina219 import INA219
from g2p.hardware.leg import HardwareCounters, HardwareLeg, HardwareLegConfig
from g2p.hardware.ls7366r import LS7366R, BeltOdometer
from g2p.hardware.outputs import MotorOutputs, PwmOutputs
from g2p.hardware.pca9685 import PCA9685
from g2p.hardware.sysfs_pwm import SysfsPwmChannel, SysfsPwmGroup
from g2p.hardware.wiring import (
    BeltConfig,
    CurrentSensorsConfig,
    EncoderConfig,
    EncodersConfig,
    MotorEnableConfig,
    PwmBackend,
    PwmConfig,
    SpiConfig,
    WiringConfig,
    load_wiring,
    wiring_from_dict,
)

__all__ = [
    "AS5048A",
    "INA219",
    "LS7366R",
    "PCA9685",
    "BeltConfig",
    "BeltOdometer",
    "BusFactory",
    "Clock",
    "CurrentSensorsConfig",
    "DeviceError",
    "EncoderConfig",
    "EncoderError",
    "EncoderErrorFlag",
    "EncoderModel",
    "EncoderParityError",
    "EncodersConfig",
    "HardwareCounters",
    "HardwareError",
    "HardwareFault",
    "HardwareLeg",
    "HardwareLegConfig",
    "LinuxBuses",
    "MagnetStatus",
    "MonotonicClock",
    "MotorEnableConfig",
    "MotorOutputs",
    "PwmBackend",
    "PwmConfig",
    "PwmOutputs",
    "RigDevices",
    "SimulatedClock",
    "SpiConfig",
    "SysfsPwmChannel",
    "SysfsPwmGroup",
    "WiringConfig",
    "build_devices",
    "load_wiring",
    "open_devices",
    "wiring_from_dict",
]
