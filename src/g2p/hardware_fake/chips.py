"""Fake buses that answer byte for byte as the rig's chips do.

Each fake chip speaks its real protocol at the level the Linux bus sees it: `FakeAS5048A` and
`FakeLS7366R` implement spidev's `xfer2` (16-bit pipelined frames with even parity; LS7366R instruction
bytes), `FakeSMBus` turns SMBus calls into the bytes on the wire for `FakePCA9685` and `FakeINA219`
(register pointer, auto-increment, MSB-first INA219 words), `FakePwmSysfs` keeps a sysfs PWM tree in a
directory and exports channels as the kernel does. `g2p.hardware_fake.buses.FakeBuses` wires them to the
MuJoCo leg. Faults to inject are described by `FaultPlan`.
"""

from __future__ import annotations

import enum
import errno
import threading
from collections.abc import Callable, Sequence
from pathlib import Path

from g2p.hardware import as5048a as enc
from g2p.hardware import ina219 as ina
from g2p.hardware import ls7366r as cnt
from g2p.hardware import pca9685 as pca
from g2p.hardware.devices import SPI_MODE_AS5048A, SPI_MODE_LS7366R

FAULT_POLL_S = 0.05


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
