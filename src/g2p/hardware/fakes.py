"""Fake buses that answer byte for byte as the rig's chips do, backed by the MuJoCo leg.

Each fake chip speaks its real protocol at the level the Linux bus sees it: `FakeAS5048A` and
`FakeLS7366R` implement spidev's `xfer2` (16-bit pipelined frames with even parity; LS7366R instruction
bytes), `FakeSMBus` turns SMBus calls into the bytes on the wire for `FakePCA9685` and `FakeINA219`
(register pointer, auto-increment, MSB-first INA219 words), `FakePwmSysfs` keeps a sysfs PWM tree in a
directory and exports channels as the kernel does. `FakeRig` wires them to a `g2p.sim.MujocoLeg`: the
duty cycles on the motor channels (and the enable line) drive the physics, the encoders, belt counter and
current sensors read its state, so the hardware plant on fake buses moves like the leg.

    rig = load_rig_config("rig.yaml")
    fake = FakeRig(rig, FakeRigConfig(), clock=SimulatedClock())
    leg = HardwareLeg(build_devices(rig, fake), rig, clock=fake.clock)

Faults can be injected (`FakeRig.inject`, or a faults.json file in `FakeRigConfig.state_dir` for a fake
rig running in another process); the outputs are observable (`FakeRig.outputs_state`, or outputs.json in
the state directory).
"""

from __future__ import annotations

import enum
import errno
import functools
import json
import math
import os
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from g2p.config import require, require_positive
from g2p.hardware import as5048a as enc
from g2p.hardware import ina219 as ina
from g2p.hardware import ls7366r as cnt
from g2p.hardware import pca9685 as pca
from g2p.hardware.clock import Clock, MonotonicClock, SimulatedClock
from g2p.hardware.devices import SPI_MODE_AS5048A, SPI_MODE_LS7366R, RigDevices, build_devices
from g2p.hardware.errors import DeviceError
from g2p.hardware.rig_config import MotorEnableConfig, PwmBackend, RigConfig, SpiConfig
from g2p.plant import N_MOTORS, FloatArray
from g2p.sim import AIR_CARRIAGE_HEIGHT_M, MujocoLeg, MujocoLegConfig

_FAULT_POLL_S = 0.05


class FaultKind(enum.Enum):
    """Faults a fake device can be told to produce."""

    ENCODER_PARITY = "encoder_parity"
    """The encoder's answer frames arrive with one bit flipped (parity error)."""
    ENCODER_ERROR_FLAG = "encoder_error_flag"
    """The encoder sees a framing error before each frame, so its answers carry the error flag."""
    OSERROR = "oserror"
    """Bus transactions with the device raise OSError (EREMOTEIO on I2C, EIO on SPI)."""


class FaultPlan:
    """How many more transactions each kind of fault affects (-1: every one from now on)."""

    def __init__(self) -> None:
        self._remaining: dict[FaultKind, int] = {}
        self._lock = threading.Lock()

    def set(self, kind: FaultKind, count: int) -> None:
        """Affect the next `count` transactions (-1: all, 0: clear)."""
        with self._lock:
            self._remaining[kind] = count

    def take(self, kind: FaultKind) -> bool:
        """Whether this transaction has the fault (consumes one)."""
        with self._lock:
            n = self._remaining.get(kind, 0)
            if n == 0:
                return False
            if n > 0:
                self._remaining[kind] = n - 1
            return True


def _no_access() -> None:
    pass


# ------------------------------------------------------------------------------------------------ SPI
class FakeAS5048A:
    """An AS5048A (or AS5047P) on a chip select: 16-bit frames, even parity, pipelined answers.

    Args:
        angle_counts: the raw angle (0..16383) the sensor measures now.
        model: the chip (its diagnostics register address).
        mode: the SPI mode it needs (1); a device opened in another mode reads shifted bits.
        on_access: called before every transfer (lets the physics catch up).
    """

    def __init__(
        self,
        angle_counts: Callable[[], int],
        model: enc.EncoderModel = enc.EncoderModel.AS5048A,
        on_access: Callable[[], None] = _no_access,
    ) -> None:
        self._angle = angle_counts
        self.model = model
        self.mode = SPI_MODE_AS5048A
        self.required_mode = SPI_MODE_AS5048A
        self._on_access = on_access
        self._next_data = 0
        self._error_bits = 0
        self.faults = FaultPlan()
        self.frames = 0
        self.diagnostics = 0x100 | 0x80  # OCF/LF set (offset loop done), AGC 128, field in range

    def _register(self, address: int) -> int:
        if address == enc.REG_NOP:
            return 0
        if address == enc.REG_ERROR:
            bits, self._error_bits = self._error_bits, 0  # reading the error register clears it
            return bits
        if address == self.model.diagnostics_register:
            return self.diagnostics
        if address == enc.REG_MAGNITUDE:
            return 0x1000
        if address == enc.REG_ANGLE:
            return self._angle() & enc.DATA_MASK
        self._error_bits |= enc.ERROR_COMMAND_INVALID
        return 0

    def xfer2(self, data: list[int]) -> list[int]:
        """One chip-select assertion: exactly one 16-bit frame in, the answer to the previous one out."""
        self._on_access()
        if self.faults.take(FaultKind.OSERROR):
            raise OSError(errno.EIO, "Input/output error (injected)")
        self.frames += 1
        if len(data) != 2:  # not 16 clocks within the chip select: a framing error
            self._error_bits |= enc.ERROR_FRAMING
            return [0] * len(data)
        if self.faults.take(FaultKind.ENCODER_ERROR_FLAG):
            self._error_bits |= enc.ERROR_FRAMING
        word = self._next_data | (enc.ERROR_FLAG if self._error_bits else 0)
        word |= 0 if enc.has_even_parity(word) else enc.PARITY_BIT
        if self.faults.take(FaultKind.ENCODER_PARITY):
            word ^= 0x0001
        command = (data[0] << 8) | data[1]
        if not enc.has_even_parity(command):
            self._error_bits |= enc.ERROR_PARITY
            self._next_data = 0
        elif command & enc.READ_BIT:
            self._next_data = self._register(command & enc.DATA_MASK)
        else:  # writes only reach the OTP/programming registers, which this rig never uses
            self._error_bits |= enc.ERROR_COMMAND_INVALID
            self._next_data = 0
        if self.mode != self.required_mode:  # sampled on the wrong clock edge: one bit late
            word = (word >> 1) | 0x8000
        return [word >> 8, word & 0xFF]

    def close(self) -> None:
        """Nothing to release."""


class FakeLS7366R:
    """An LS7366R quadrature counter: instruction byte, then data MSB first.

    Args:
        edges: the number of quadrature edges (x4 counts) the encoder has produced so far.
        on_access: called before every transfer.
    """

    def __init__(self, edges: Callable[[], int], on_access: Callable[[], None] = _no_access) -> None:
        self._edges = edges
        self._on_access = on_access
        self.mode = SPI_MODE_LS7366R
        self.mdr0 = 0
        self.mdr1 = 0
        self.dtr = 0
        self.otr = 0
        self.status = 0
        self._origin = 0  # counts at the last clear, in the current quadrature mode's units
        self._frozen: int | None = None
        self.faults = FaultPlan()

    @property
    def n_bytes(self) -> int:
        """Counter width in bytes (MDR1 bits 1..0: 00 = 4 bytes ... 11 = 1 byte)."""
        return 4 - (self.mdr1 & 0x3)

    def _scaled(self) -> int:
        divisor = {0: 4, 1: 4, 2: 2, 3: 1}[self.mdr0 & 0x3]
        return self._edges() // divisor

    def _counter(self) -> int:
        raw = self._frozen if self._frozen is not None else self._scaled() - self._origin
        return raw & ((1 << (8 * self.n_bytes)) - 1)

    def _set_counter(self, value: int) -> None:
        self._origin = self._scaled() - value
        if self._frozen is not None:
            self._frozen = value

    def xfer2(self, data: list[int]) -> list[int]:
        """One chip-select assertion: instruction byte, then data in or out."""
        self._on_access()
        if self.faults.take(FaultKind.OSERROR):
            raise OSError(errno.EIO, "Input/output error (injected)")
        rx = [0] * len(data)
        if not data:
            return rx
        op, reg = data[0] & 0xC0, data[0] & 0x38
        if self.mode != SPI_MODE_LS7366R:
            return [0xFF] * len(data)
        if op == cnt.OP_CLR:
            if reg == cnt.REG_MDR0:
                self.mdr0 = 0
            elif reg == cnt.REG_MDR1:
                self.mdr1 = 0
            elif reg == cnt.REG_CNTR:
                self._set_counter(0)
            elif reg == cnt.REG_STR:
                self.status = 0
        elif op == cnt.OP_RD:
            if reg in (cnt.REG_CNTR, cnt.REG_OTR, cnt.REG_DTR):
                if reg == cnt.REG_CNTR:
                    self.otr = self._counter()  # RD CNTR goes through OTR
                value = self.dtr if reg == cnt.REG_DTR else self.otr
                out = list(value.to_bytes(self.n_bytes, "big"))
            else:
                out = [
                    {cnt.REG_MDR0: self.mdr0, cnt.REG_MDR1: self.mdr1, cnt.REG_STR: self._status()}.get(
                        reg, 0
                    )
                ]
            for i in range(1, len(data)):
                rx[i] = out[i - 1] if i - 1 < len(out) else 0
        elif op == cnt.OP_WR:
            payload = data[1:]
            if reg == cnt.REG_MDR0 and payload:
                self.mdr0 = payload[0]
            elif reg == cnt.REG_MDR1 and payload:
                counting = not (payload[0] & 0x04)
                if not counting and self._frozen is None:
                    self._frozen = self._counter()
                elif counting and self._frozen is not None:
                    self._set_counter(self._frozen)
                    self._frozen = None
                self.mdr1 = payload[0]
            elif reg == cnt.REG_DTR:
                self.dtr = int.from_bytes(bytes(payload[: self.n_bytes]), "big")
        elif op == cnt.OP_LOAD:
            if reg == cnt.REG_CNTR:
                self._set_counter(self.dtr)
            elif reg == cnt.REG_OTR:
                self.otr = self._counter()
        return rx

    def _status(self) -> int:
        value = self._counter()
        negative = value >> (8 * self.n_bytes - 1) & 1
        enabled = 0 if self.mdr1 & 0x04 else cnt.STR_COUNT_ENABLED
        return self.status | negative | enabled

    def close(self) -> None:
        """Nothing to release."""


class FloatingSpi:
    """A chip select with nothing on it: MISO is pulled up, every byte reads 0xFF."""

    def __init__(self) -> None:
        self.mode = 0

    def xfer2(self, data: list[int]) -> list[int]:
        """Clock bytes out; read 0xFF."""
        return [0xFF] * len(data)

    def close(self) -> None:
        """Nothing to release."""


# ------------------------------------------------------------------------------------------------ I2C
class FakeI2cChip:
    """An I2C slave at the byte level: a write transaction, or a read from the register pointer."""

    def __init__(self) -> None:
        self.faults = FaultPlan()

    def write(self, data: Sequence[int]) -> None:
        """A write transaction: the pointer byte, then data bytes."""
        raise NotImplementedError

    def read(self, length: int) -> list[int]:
        """A read transaction of `length` bytes from the register pointer."""
        raise NotImplementedError


class FakePCA9685(FakeI2cChip):
    """A PCA9685: 256-byte register file with the chip's MODE1/PRE_SCALE/ALL_LED behaviour.

    Args:
        on_change: called after a write that may have changed the outputs.
    """

    def __init__(self, on_change: Callable[[], None] = _no_access) -> None:
        super().__init__()
        self.regs = [0] * 256
        self.regs[pca.REG_MODE1] = pca.MODE1_SLEEP | pca.MODE1_ALLCALL  # power-on 0x11
        self.regs[pca.REG_MODE2] = pca.MODE2_OUTDRV  # power-on 0x04
        self.regs[pca.REG_PRESCALE] = 0x1E  # power-on: 200 Hz
        for ch in range(pca.N_CHANNELS):
            self.regs[pca.REG_LED0_ON_L + 4 * ch + 3] = pca.FULL_BIT  # power-on: full off
        self._pointer = 0
        self._paused = [False] * pca.N_CHANNELS  # stopped by SLEEP until RESTART or a rewrite
        self._on_change = on_change

    @property
    def sleeping(self) -> bool:
        """Whether the oscillator is off (MODE1 SLEEP)."""
        return bool(self.regs[pca.REG_MODE1] & pca.MODE1_SLEEP)

    @property
    def frequency_hz(self) -> float:
        """The PWM frequency the prescaler sets (Hz)."""
        return pca.INTERNAL_OSC_HZ / (pca.PERIOD_COUNTS * (self.regs[pca.REG_PRESCALE] + 1))

    def channel_registers(self, channel: int) -> list[int]:
        """LEDn_ON_L, ON_H, OFF_L, OFF_H of a channel."""
        base = pca.REG_LED0_ON_L + 4 * channel
        return self.regs[base : base + 4]

    def output_duty(self, channel: int) -> float:
        """The duty cycle on the channel's pin now (0 while asleep or stopped by a sleep)."""
        if self.sleeping or self._paused[channel]:
            return 0.0
        return pca.duty_of(self.channel_registers(channel))

    def _advance(self) -> None:
        if self.regs[pca.REG_MODE1] & pca.MODE1_AI:
            self._pointer = 0 if self._pointer == 0x45 else (self._pointer + 1) & 0xFF

    def _store(self, reg: int, value: int) -> None:
        if reg == pca.REG_MODE1:
            was_sleeping = self.sleeping
            old_restart = self.regs[reg] & pca.MODE1_RESTART
            new = value & ~pca.MODE1_RESTART
            if value & pca.MODE1_RESTART and old_restart and not (value & pca.MODE1_SLEEP):
                self._paused = [False] * pca.N_CHANNELS  # writing 1 to RESTART restarts and clears it
                old_restart = 0
            if value & pca.MODE1_SLEEP and not was_sleeping:
                running = [pca.duty_of(self.channel_registers(c)) > 0 for c in range(pca.N_CHANNELS)]
                if any(running):
                    self._paused = running
                    old_restart = pca.MODE1_RESTART
            self.regs[reg] = new | old_restart
        elif reg == pca.REG_PRESCALE:
            if self.sleeping:  # PRE_SCALE is only writable while asleep
                self.regs[reg] = value
        elif pca.REG_ALL_LED_ON_L <= reg <= pca.REG_ALL_LED_OFF_H:
            offset = reg - pca.REG_ALL_LED_ON_L
            for ch in range(pca.N_CHANNELS):
                self.regs[pca.REG_LED0_ON_L + 4 * ch + offset] = value
                self._paused[ch] = False
        else:
            if pca.REG_LED0_ON_L <= reg < pca.REG_LED0_ON_L + 4 * pca.N_CHANNELS:
                self._paused[(reg - pca.REG_LED0_ON_L) // 4] = False
            self.regs[reg] = value

    def write(self, data: Sequence[int]) -> None:
        """Pointer, then bytes stored with auto-increment when MODE1 AI is set (else all to one register)."""
        if not data:
            return
        self._pointer = data[0]
        for i, value in enumerate(data[1:]):
            if i > 0:
                self._advance()
            self._store(self._pointer, value & 0xFF)
        self._on_change()

    def read(self, length: int) -> list[int]:
        """Bytes from the pointer on (ALL_LED registers read as 0), auto-incrementing when AI is set."""
        out = []
        for i in range(length):
            if i > 0:
                self._advance()
            reg = self._pointer
            out.append(0 if pca.REG_ALL_LED_ON_L <= reg <= pca.REG_ALL_LED_OFF_H else self.regs[reg])
        return out


class FakeINA219(FakeI2cChip):
    """An INA219: 16-bit registers sent MSB first, current and power computed from the calibration.

    Args:
        shunt_ohm: the shunt on the board (ohm).
        measure: the current through the shunt (A, signed) and the bus voltage (V) now.
    """

    def __init__(self, shunt_ohm: float, measure: Callable[[], tuple[float, float]]) -> None:
        super().__init__()
        self.shunt_ohm = shunt_ohm
        self._measure = measure
        self._pointer = 0
        self.config = ina.CONFIG_POWER_ON
        self.calibration = 0

    def _shunt_raw(self, current_a: float) -> int:
        pga = (self.config >> ina.PGA_SHIFT) & 0x3
        limit = 4000 << pga  # +-40 mV .. +-320 mV in 10 uV counts
        return int(max(-limit, min(limit, round(current_a * self.shunt_ohm / ina.SHUNT_LSB_V))))

    def _register(self, reg: int) -> int:
        if reg == ina.REG_CONFIG:
            return self.config
        if reg == ina.REG_CALIBRATION:
            return self.calibration
        current_a, bus_v = self._measure()
        shunt = self._shunt_raw(current_a)
        bus = max(0, min(0x1FFF, round(bus_v / ina.BUS_LSB_V)))
        current = int(shunt * self.calibration / 4096)
        overflow = not -0x8000 <= current <= 0x7FFF
        current = max(-0x8000, min(0x7FFF, current))
        if reg == ina.REG_SHUNT_VOLTAGE:
            return shunt & 0xFFFF
        if reg == ina.REG_BUS_VOLTAGE:
            return (bus << 3) | ina.BUS_CNVR | (ina.BUS_OVF if overflow else 0)
        if reg == ina.REG_CURRENT:
            return current & 0xFFFF
        if reg == ina.REG_POWER:
            return min(0xFFFF, abs(current) * bus // 5000)
        return 0

    def write(self, data: Sequence[int]) -> None:
        """Pointer byte, then (optionally) a 16-bit value MSB first."""
        if not data:
            return
        self._pointer = data[0]
        if len(data) < 3:
            return
        value = ((data[1] & 0xFF) << 8) | (data[2] & 0xFF)
        if self._pointer == ina.REG_CONFIG:
            if value & ina.CONFIG_RESET:
                self.config, self.calibration = ina.CONFIG_POWER_ON, 0
            else:
                self.config = value
        elif self._pointer == ina.REG_CALIBRATION:
            self.calibration = value & 0xFFFE  # bit 0 is read-only zero

    def read(self, length: int) -> list[int]:
        """The register at the pointer, MSB first (repeated for longer reads)."""
        value = self._register(self._pointer)
        return [(value >> 8) & 0xFF if i % 2 == 0 else value & 0xFF for i in range(length)]


class FakeSMBus:
    """An I2C adapter with fake chips at their addresses; SMBus calls become the bytes on the wire.

    SMBus word transactions put the low byte first on the wire, like the Linux SMBus layer; an address
    with no chip (or a failing one) raises OSError(EREMOTEIO), as i2c-bcm2835 does on a missing ACK.

    Args:
        bus: the bus number (for messages).
        on_access: called before every transaction.
    """

    def __init__(self, bus: int = 1, on_access: Callable[[], None] = _no_access) -> None:
        self.bus = bus
        self.chips: dict[int, FakeI2cChip] = {}
        self._on_access = on_access
        self.transactions = 0
        self.closed = False

    def _chip(self, addr: int) -> FakeI2cChip:
        self._on_access()
        self.transactions += 1
        if self.closed:
            raise OSError(errno.EBADF, "Bad file descriptor")
        chip = self.chips.get(addr)
        if chip is None or chip.faults.take(FaultKind.OSERROR):
            raise OSError(errno.EREMOTEIO, f"Remote I/O error (i2c-{self.bus} address {addr:#04x})")
        return chip

    def read_byte_data(self, i2c_addr: int, register: int) -> int:
        """Write the pointer, read one byte."""
        chip = self._chip(i2c_addr)
        chip.write([register])
        return chip.read(1)[0]

    def write_byte_data(self, i2c_addr: int, register: int, value: int) -> None:
        """Write the pointer and one byte."""
        self._chip(i2c_addr).write([register, value & 0xFF])

    def read_word_data(self, i2c_addr: int, register: int) -> int:
        """Write the pointer, read two bytes; the first byte on the wire is the low byte of the result."""
        chip = self._chip(i2c_addr)
        chip.write([register])
        lo, hi = chip.read(2)
        return lo | (hi << 8)

    def write_word_data(self, i2c_addr: int, register: int, value: int) -> None:
        """Write the pointer, then the low byte, then the high byte."""
        self._chip(i2c_addr).write([register, value & 0xFF, (value >> 8) & 0xFF])

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int) -> list[int]:
        """Write the pointer, read `length` bytes."""
        chip = self._chip(i2c_addr)
        chip.write([register])
        return chip.read(length)

    def write_i2c_block_data(self, i2c_addr: int, register: int, data: Sequence[int]) -> None:
        """Write the pointer and the bytes."""
        self._chip(i2c_addr).write([register, *[d & 0xFF for d in data]])

    def close(self) -> None:
        """Further transactions fail, as on a closed file descriptor."""
        self.closed = True


# ------------------------------------------------------------------------------------------------ GPIO
class FakeOutputLine:
    """A GPIO output line: remembers its logical value and every change.

    Args:
        on_change: called after every change.
    """

    def __init__(self, on_change: Callable[[], None] = _no_access) -> None:
        self.active = False
        self.released = False
        self.history: list[bool] = [False]
        self.faults = FaultPlan()
        self._on_change = on_change

    def set_value(self, active: bool) -> None:
        """Drive the line; OSError when a fault is injected or the request was released."""
        if self.released or self.faults.take(FaultKind.OSERROR):
            raise OSError(errno.EIO, "Input/output error")
        self.active = active
        self.history.append(active)
        self._on_change()

    def close(self) -> None:
        """Release the line: it goes inactive (the board's pull-down)."""
        self.released = True
        self.active = False
        self._on_change()


# ------------------------------------------------------------------------------------------------ sysfs
class FakePwmSysfs:
    """A sysfs PWM chip in a directory: pwmchipN/{npwm,export,unexport} and pwmM/ on export.

    A background thread plays the kernel: it reacts to writes to export/unexport within a few ms (as udev
    does, the files appear a moment after the write). The channel files are plain files, so the state of
    the outputs can be read back by anyone, from any process.

    Args:
        root: the directory standing for /sys/class/pwm.
        chip: N of pwmchipN.
        npwm: number of channels.
    """

    def __init__(self, root: Path, chip: int = 0, npwm: int = 4) -> None:
        self.root = Path(root)
        self.chip_dir = self.root / f"pwmchip{chip}"
        self.chip_dir.mkdir(parents=True, exist_ok=True)
        (self.chip_dir / "npwm").write_text(f"{npwm}\n")
        for name in ("export", "unexport"):
            (self.chip_dir / name).write_text("")
        self.npwm = npwm
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._kernel, name="fake_sysfs_pwm", daemon=True)
        self._thread.start()

    def channel_dir(self, channel: int) -> Path:
        """pwmchipN/pwmM."""
        return self.chip_dir / f"pwm{channel}"

    def export(self, channel: int) -> None:
        """Create a channel directory as the kernel does on export (period 0, duty 0, disabled)."""
        d = self.channel_dir(channel)
        if d.is_dir():
            return
        d.mkdir()
        for name, value in (("period", "0"), ("duty_cycle", "0"), ("enable", "0"), ("polarity", "normal")):
            (d / name).write_text(value + "\n")

    def channel_state(self, channel: int) -> tuple[int, int, bool]:
        """(period ns, duty ns, enabled) of an exported channel; (0, 0, False) otherwise."""
        d = self.channel_dir(channel)
        try:
            return (
                int((d / "period").read_text() or 0),
                int((d / "duty_cycle").read_text() or 0),
                (d / "enable").read_text().strip() == "1",
            )
        except (OSError, ValueError):
            return 0, 0, False

    def output_duty(self, channel: int) -> float:
        """The duty cycle on the pin (0 unless enabled with 0 < duty <= period)."""
        period, duty, enabled = self.channel_state(channel)
        if not enabled or period <= 0 or not 0 <= duty <= period:
            return 0.0
        return duty / period

    def _kernel(self) -> None:
        while not self._stop.wait(0.002):
            for name in ("export", "unexport"):
                path = self.chip_dir / name
                try:
                    text = path.read_text().strip()
                except OSError:
                    continue
                if not text:
                    continue
                path.write_text("")
                try:
                    channel = int(text)
                except ValueError:
                    continue
                if not 0 <= channel < self.npwm:
                    continue
                if name == "export":
                    self.export(channel)
                else:
                    d = self.channel_dir(channel)
                    for f in d.glob("*"):
                        f.unlink()
                    d.rmdir()

    def close(self) -> None:
        """Stop the kernel thread (the files stay, with the last state)."""
        self._stop.set()
        self._thread.join(1.0)


# ------------------------------------------------------------------------------------------------ the rig
@dataclass(frozen=True)
class FakeRigConfig:
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


class FakeRig:
    """The whole rig on fake buses: a `BusFactory` whose chips read and drive a MuJoCo leg.

    Args:
        rig: the rig description the driver uses (where each chip sits, the PWM map).
        config: physics and observability settings.
        clock: the clock the physics follows (the hardware plant must use the same one); None uses the
            monotonic clock (real time, as in the driver with fake devices).
        truth: how the sensors are really mounted (zero offsets, directions), if not as `rig` says: a
            miswired rig for bring-up tests.
    """

    def __init__(
        self,
        rig: RigConfig,
        config: FakeRigConfig | None = None,
        clock: Clock | None = None,
        truth: RigConfig | None = None,
    ) -> None:
        self.rig = rig
        self.config = cfg = config if config is not None else FakeRigConfig()
        self.truth = truth if truth is not None else rig
        self.clock = clock if clock is not None else MonotonicClock()
        self._lock = threading.RLock()
        self.leg = MujocoLeg(
            MujocoLegConfig(
                carriage_height_m=cfg.carriage_height_m,
                tick_hz=cfg.physics_hz,
                tick_jitter_s=0.0,
                substeps=max(1, round(1000.0 / cfg.physics_hz)),  # about 1 ms physics steps
                baseline_activation=0.0,  # the motors can be off: the tendons then go slack
                settle_s=1.0,
                seed=cfg.seed,
            )
        )
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

        enc_cfg = (rig.encoders.proximal, rig.encoders.distal)
        self.encoders = tuple(
            FakeAS5048A(functools.partial(self._encoder_counts, j), e.model, self.advance)
            for j, e in enumerate(enc_cfg)
        )
        self.counter = FakeLS7366R(self._belt_edges, self.advance)
        self._spi: dict[tuple[int, int], Any] = {
            (enc_cfg[0].spi.bus, enc_cfg[0].spi.chip_select): self.encoders[0],
            (enc_cfg[1].spi.bus, enc_cfg[1].spi.chip_select): self.encoders[1],
            (rig.belt.spi.bus, rig.belt.spi.chip_select): self.counter,
        }
        self.i2c_buses: dict[int, FakeSMBus] = {}
        cs = rig.current_sensors
        self.current_sensors = tuple(
            FakeINA219(cs.shunt_ohm, functools.partial(self._supply, i)) for i in range(N_MOTORS)
        )
        for addr, chip in zip(cs.addresses, self.current_sensors, strict=True):
            self._bus(cs.i2c_bus).chips[addr] = chip
        self.pca: FakePCA9685 | None = None
        self.sysfs: FakePwmSysfs | None = None
        self._sysfs_tmp: Any = None
        if rig.pwm.backend is PwmBackend.PCA9685:
            self.pca = FakePCA9685(self._outputs_changed)
            self._bus(rig.pwm.i2c_bus).chips[rig.pwm.address] = self.pca
        else:
            self.sysfs = FakePwmSysfs(self._sysfs_root(), rig.pwm.sysfs_chip, npwm=max(rig.pwm.channels) + 1)
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
        if self.rig.motor_enable is not None and (self.enable_line is None or not self.enable_line.active):
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
        p = self.rig.pwm
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
        if self._state_dir is None or time.monotonic() - self._faults_checked < _FAULT_POLL_S:
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
    rig: RigConfig, config: FakeRigConfig | None = None, clock: Clock | None = None
) -> tuple[FakeRig, RigDevices]:
    """A fake rig and its devices set up by the real set-up code (`build_devices`).

    Returns:
        (the fake rig, the `RigDevices` on its buses).
    """
    fake = FakeRig(rig, config, clock)
    return fake, build_devices(rig, fake)


__all__ = [
    "FakeAS5048A",
    "FakeINA219",
    "FakeLS7366R",
    "FakeOutputLine",
    "FakePCA9685",
    "FakePwmSysfs",
    "FakeRig",
    "FakeRigConfig",
    "FakeSMBus",
    "FaultKind",
    "FaultPlan",
    "FloatingSpi",
    "SimulatedClock",
    "fake_devices",
]
