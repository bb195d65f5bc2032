"""The whole rig on fake buses (`g2p.hardware_fake.chips`), backed by the MuJoCo leg.

`FakeBuses` wires the fake chips to a `g2p.sim.MujocoLeg`: the duty cycles on the motor channels (and the
enable line) drive the physics, the encoders, belt counter and current sensors read its state, so the
hardware plant on fake buses moves like the leg. This module imports MuJoCo; the fake chips do not.

    wiring = load_wiring("wiring.yaml")
    fake = FakeBuses(wiring, FakeBusesConfig(), clock=SimulatedClock())
    leg = HardwareLeg(build_devices(wiring, fake), wiring, clock=fake.clock)

Faults can be injected (`FakeBuses.inject`, or a faults.json file in `FakeBusesConfig.state_dir` for a fake
rig running in another process); the outputs are observable (`FakeBuses.outputs_state`, or outputs.json in
the state directory).
"""

from __future__ import annotations

import functools
import json
import math
import os
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from g2p.hardware import as5048a as enc
from g2p.hardware.clock import Clock, MonotonicClock, SimulatedClock
from g2p.hardware.devices import RigDevices, build_devices
from g2p.hardware.errors import DeviceError
from g2p.hardware.wiring import MotorEnableConfig, PwmBackend, SpiConfig, WiringConfig
from g2p.hardware_fake.chips import (
    FAULT_POLL_S,
    FakeAS5048A,
    FakeINA219,
    FakeLS7366R,
    FakeOutputLine,
    FakePCA9685,
    FakePwmSysfs,
    FakeSMBus,
    FaultKind,
    FaultPlan,
    FloatingSpi,
)
from g2p.plant import N_MOTORS, FloatArray
from g2p.sim import AIR_CARRIAGE_HEIGHT_M, MujocoLeg, MujocoLegConfig
from g2p.validation import require, require_positive


@dataclass(frozen=True)
class FakeBusesConfig:
    """The physics and observability of the fake rig.

    Attributes:
        carriage_height_m: hip axis above the belt (m): 0.6 hangs the foot in the air, 0.42 stands it on
            the treadmill.
        physics_hz: rate of the physics chunks the fake advances by (Hz); the bus reads see the state at
            the end of the last chunk.
        supply_voltage_v: the motor drivers' supply voltage the current sensors measure (V).
        state_dir: directory for outputs.json (the output state, rewritten on every change) and
            faults.json (faults to inject, read when it changes); "" for neither.
        seed: seed of the physics (jitter-free here, but kept for MujocoLeg).
    """

    carriage_height_m: float = AIR_CARRIAGE_HEIGHT_M
    physics_hz: float = 500.0
    supply_voltage_v: float = 24.0
    state_dir: str = ""
    seed: int = 0

    def __post_init__(self) -> None:
        require_positive(self.carriage_height_m, "carriage_height_m")
        require(
            math.isfinite(self.physics_hz) and 50.0 <= self.physics_hz <= 5000.0,
            "physics_hz",
            f"must be in [50, 5000] Hz, got {self.physics_hz!r}",
        )
        require_positive(self.supply_voltage_v, "supply_voltage_v")


def fake_leg_config(config: FakeBusesConfig) -> MujocoLegConfig:
    """The MuJoCo leg behind the fake buses (the driver describes its model as robot_description)."""
    return MujocoLegConfig(
        carriage_height_m=config.carriage_height_m,
        tick_hz=config.physics_hz,
        tick_jitter_s=0.0,
        substeps=max(1, round(1000.0 / config.physics_hz)),  # about 1 ms physics steps
        baseline_activation=0.0,  # the motors can be off: the tendons then go slack
        settle_s=1.0,
        seed=config.seed,
    )


class FakeBuses:
    """The whole rig on fake buses: a `BusFactory` whose chips read and drive a MuJoCo leg.

    Args:
        wiring: the wiring description the driver uses (where each chip sits, the PWM map).
        config: physics and observability settings.
        clock: the clock the physics follows (the hardware plant must use the same one); None uses the
            monotonic clock (real time, as in the driver with fake devices).
        truth: how the sensors are really mounted (zero offsets, directions), if not as `rig` says: a
            miswired rig for tendon-check tests.
    """

    def __init__(
        self,
        wiring: WiringConfig,
        config: FakeBusesConfig | None = None,
        clock: Clock | None = None,
        truth: WiringConfig | None = None,
    ) -> None:
        self.wiring = wiring
        self.config = cfg = config if config is not None else FakeBusesConfig()
        self.truth = truth if truth is not None else wiring
        self.clock = clock if clock is not None else MonotonicClock()
        self._lock = threading.RLock()
        self.leg = MujocoLeg(fake_leg_config(cfg))
        rest = self.leg.reset()
        self._belt_mm = rest.belt_mm
        self._power_w = np.zeros(N_MOTORS)
        self._dt = 1.0 / cfg.physics_hz
        self._t_phys = self.clock.now()
        self._activation = np.zeros(N_MOTORS)
        self.physics_steps = 0
        self.closed = False

        self._state_dir = Path(cfg.state_dir) if cfg.state_dir else None
        self._written_state = ""
        self._faults_mtime = 0
        self._faults_checked = 0.0
        if self._state_dir is not None:
            self._state_dir.mkdir(parents=True, exist_ok=True)

        enc_cfg = (wiring.encoders.proximal, wiring.encoders.distal)
        self.encoders = tuple(
            FakeAS5048A(functools.partial(self._encoder_counts, j), e.model, self.advance)
            for j, e in enumerate(enc_cfg)
        )
        self.counter = FakeLS7366R(self._belt_edges, self.advance)
        self._spi: dict[tuple[int, int], Any] = {
            (enc_cfg[0].spi.bus, enc_cfg[0].spi.chip_select): self.encoders[0],
            (enc_cfg[1].spi.bus, enc_cfg[1].spi.chip_select): self.encoders[1],
            (wiring.belt.spi.bus, wiring.belt.spi.chip_select): self.counter,
        }
        self.i2c_buses: dict[int, FakeSMBus] = {}
        cs = wiring.current_sensors
        self.current_sensors = tuple(
            FakeINA219(cs.shunt_ohm, functools.partial(self._supply, i)) for i in range(N_MOTORS)
        )
        for addr, chip in zip(cs.addresses, self.current_sensors, strict=True):
            self._bus(cs.i2c_bus).chips[addr] = chip
        self.pca: FakePCA9685 | None = None
        self.sysfs: FakePwmSysfs | None = None
        self._sysfs_tmp: Any = None
        if wiring.pwm.backend is PwmBackend.PCA9685:
            self.pca = FakePCA9685(self._outputs_changed)
            self._bus(wiring.pwm.i2c_bus).chips[wiring.pwm.address] = self.pca
        else:
            self.sysfs = FakePwmSysfs(
                self._sysfs_root(), wiring.pwm.sysfs_chip, npwm=max(wiring.pwm.channels) + 1
            )
        self.enable_line: FakeOutputLine | None = None
        self._write_state()

    # ------------------------------------------------------------------------------------------ BusFactory
    def spi(self, config: SpiConfig, mode: int) -> Any:
        """The fake chip at that chip select (or a floating bus), set to `mode`."""
        dev = self._spi.get((config.bus, config.chip_select))
        if dev is None:
            dev = self._spi[(config.bus, config.chip_select)] = FloatingSpi()
        dev.mode = mode
        return dev

    def i2c(self, bus: int) -> FakeSMBus:
        """The fake I2C adapter with that number."""
        b = self._bus(bus)
        b.closed = False
        return b

    def output_line(self, config: MotorEnableConfig) -> FakeOutputLine:
        """The drivers' enable line, inactive."""
        self.enable_line = FakeOutputLine(self._outputs_changed)
        return self.enable_line

    def pwm_root(self, configured: str) -> Path:
        """The fake sysfs tree, whatever the configured root."""
        if self.sysfs is None:
            raise DeviceError("this fake rig has no sysfs PWM (the rig uses the pca9685 backend)")
        return self.sysfs.root

    def close(self) -> None:
        """Release the buses (further I2C transactions fail) and stop the sysfs kernel thread."""
        with self._lock:
            self.advance()
            self.closed = True
            for b in self.i2c_buses.values():
                b.closed = True
            if self.sysfs is not None:
                self.sysfs.close()
            self._write_state()

    # ------------------------------------------------------------------------------------------ physics
    def advance(self) -> None:
        """Run the physics up to the clock's time, with the activations the outputs command now."""
        with self._lock:
            now = self.clock.now()
            self._poll_fault_file(now)
            if self.sysfs is not None:
                self._activation = self._commanded_activation()
            while self._t_phys + self._dt <= now:
                sample = self.leg.step(self._activation)
                self._t_phys += self._dt
                self.physics_steps += 1
                self._belt_mm = sample.belt_mm
                self._power_w = sample.power_w

    def _commanded_activation(self) -> FloatArray:
        """What the motor drivers make of their inputs: 0 when disabled or the set value is out of range."""
        p = self.truth.pwm  # the motors as they are really wired (channels) and how their drivers read PWM
        if self.wiring.motor_enable is not None and (self.enable_line is None or not self.enable_line.active):
            return np.zeros(N_MOTORS)
        act = np.zeros(N_MOTORS)
        for i, ch in enumerate(p.channels):
            duty = self.pca.output_duty(ch) if self.pca is not None else self._sysfs_duty(ch)
            if p.duty_at_zero - 1e-9 <= duty <= p.duty_at_full + 1e-9:
                act[i] = min(1.0, max(0.0, p.activation(duty)))
        return act

    def _sysfs_duty(self, channel: int) -> float:
        assert self.sysfs is not None
        return self.sysfs.output_duty(channel)

    def _outputs_changed(self) -> None:
        with self._lock:
            self._activation = self._commanded_activation()
            self._write_state()

    def _encoder_counts(self, joint: int) -> int:
        e = (self.truth.encoders.proximal, self.truth.encoders.distal)[joint]
        angle = float(self.leg.true_position_rad[joint])
        return round(e.zero_offset_counts + e.direction * angle * enc.COUNTS_PER_TURN / (2.0 * math.pi)) % (
            enc.COUNTS_PER_TURN
        )

    def _belt_edges(self) -> int:
        b = self.truth.belt
        edges_per_rev = b.counts_per_rev * 4 / b.quadrature
        return round(b.direction * self._belt_mm / (2.0 * math.pi * b.drum_radius_mm) * edges_per_rev)

    def _supply(self, motor: int) -> tuple[float, float]:
        v = self.config.supply_voltage_v
        return float(self._power_w[motor]) / v, v

    # ------------------------------------------------------------------------------------------ observing
    @property
    def belt_mm(self) -> float:
        """The true belt travel (mm, + backward) at the end of the last physics chunk."""
        return self._belt_mm

    @property
    def activation(self) -> FloatArray:
        """The activations the motor drivers apply now, shape (3,)."""
        return self._activation.copy()

    def outputs_state(self) -> dict[str, Any]:
        """The outputs as a JSON-able dict: enable line, duty per motor channel, activation, time."""
        p = self.wiring.pwm
        duties = [
            (self.pca.output_duty(ch) if self.pca is not None else self._sysfs_duty(ch)) for ch in p.channels
        ]
        return {
            "enabled": None if self.enable_line is None else self.enable_line.active,
            "duty": duties,
            "activation": self._activation.tolist(),
            "pwm_sleeping": self.pca.sleeping if self.pca is not None else None,
            "closed": self.closed,
            "time_s": self.clock.now(),
        }

    def inject(self, kind: FaultKind, target: str, count: int = -1) -> None:
        """Make a device fail: `count` transactions (-1: from now on, 0: stop).

        Args:
            kind: the fault.
            target: "proximal", "distal" (encoders), "belt", "M0".."M2" (current sensors), "pwm", "enable".
            count: transactions affected.

        Raises:
            ValueError: unknown target, or a fault the target cannot produce.
        """
        devices: dict[str, Any] = {
            "proximal": self.encoders[0],
            "distal": self.encoders[1],
            "belt": self.counter,
            "M0": self.current_sensors[0],
            "M1": self.current_sensors[1],
            "M2": self.current_sensors[2],
            "pwm": self.pca,
            "enable": self.enable_line,
        }
        dev = devices.get(target)
        if dev is None:
            raise ValueError(f"target: unknown or absent device {target!r}; known: {sorted(devices)}")
        if kind is not FaultKind.OSERROR and not isinstance(dev, FakeAS5048A):
            raise ValueError(f"{kind.value} faults need an encoder target, got {target!r}")
        dev.faults.set(kind, count)

    # ------------------------------------------------------------------------------------------ internals
    def _bus(self, number: int) -> FakeSMBus:
        if number not in self.i2c_buses:
            self.i2c_buses[number] = FakeSMBus(number, self.advance)
        return self.i2c_buses[number]

    def _sysfs_root(self) -> Path:
        if self._state_dir is not None:
            return self._state_dir / "sys" / "class" / "pwm"
        import tempfile

        self._sysfs_tmp = tempfile.TemporaryDirectory(prefix="g2p-fake-pwm-")
        return Path(self._sysfs_tmp.name)

    def _write_state(self) -> None:
        """Rewrite outputs.json when the outputs changed (atomically: readers never see half a file)."""
        if self._state_dir is None:
            return
        state = self.outputs_state()
        key = json.dumps({k: v for k, v in state.items() if k != "time_s"})
        if key == self._written_state:
            return
        self._written_state = key
        tmp = self._state_dir / "outputs.json.tmp"
        tmp.write_text(json.dumps(state))
        os.replace(tmp, self._state_dir / "outputs.json")

    def _poll_fault_file(self, now: float) -> None:
        if self._state_dir is None or time.monotonic() - self._faults_checked < FAULT_POLL_S:
            return
        self._faults_checked = time.monotonic()
        path = self._state_dir / "faults.json"
        try:
            mtime = path.stat().st_mtime_ns
        except OSError:
            return
        if mtime == self._faults_mtime:
            return
        self._faults_mtime = mtime
        for item in json.loads(path.read_text()):
            self.inject(FaultKind(item["kind"]), item["target"], int(item.get("count", -1)))


def fake_devices(
    wiring: WiringConfig, config: FakeBusesConfig | None = None, clock: Clock | None = None
) -> tuple[FakeBuses, RigDevices]:
    """A fake rig and its devices set up by the real set-up code (`build_devices`).

    Returns:
        (the fake rig, the `RigDevices` on its buses).
    """
    fake = FakeBuses(wiring, config, clock)
    return fake, build_devices(wiring, fake)


__all__ = [
    "FakeAS5048A",
    "FakeBuses",
    "FakeBusesConfig",
    "FakeINA219",
    "FakeLS7366R",
    "FakeOutputLine",
    "FakePCA9685",
    "FakePwmSysfs",
    "FakeSMBus",
    "FaultKind",
    "FaultPlan",
    "FloatingSpi",
    "SimulatedClock",
    "fake_devices",
]
