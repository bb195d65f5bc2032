"""Linux sysfs PWM (Documentation/ABI/testing/sysfs-class-pwm): /sys/class/pwm/pwmchipN/pwmM.

Writing M to pwmchipN/export creates pwmchipN/pwmM/ with `period`, `duty_cycle` (both ns), `enable` (0/1)
and `polarity`; writing M to `unexport` removes it. The kernel rejects a duty_cycle above the period
(EINVAL), so a new period is written after lowering the duty cycle when needed. After an export, udev may
take a moment to make the new files writable: `open` waits for that. Paths hang off a root directory
argument, so tests run against a tree in a temporary directory.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path

from g2p.hardware.errors import DeviceError

DEFAULT_ROOT = Path("/sys/class/pwm")


def _write(path: Path, value: int | str) -> None:
    with open(path, "w") as f:
        f.write(f"{value}\n")


def _read_int(path: Path) -> int:
    return int(path.read_text().strip())


class SysfsPwmChannel:
    """One sysfs PWM channel.

    Args:
        root: the pwm class directory (/sys/class/pwm on the rig).
        chip: N of pwmchipN.
        channel: M of pwmM.
        export_timeout_s: how long to wait for the channel to appear and become writable after export (s).
    """

    def __init__(self, root: Path, chip: int, channel: int, export_timeout_s: float = 2.0) -> None:
        self.chip_dir = Path(root) / f"pwmchip{chip}"
        self.channel = channel
        self.dir = self.chip_dir / f"pwm{channel}"
        self.export_timeout_s = export_timeout_s
        self._exported_here = False
        self.period_ns = 0

    def open(self) -> None:
        """Export the channel unless it already is, and wait until its files are writable.

        Raises:
            DeviceError: no such chip or channel, or the channel never appeared.
        """
        if not self.chip_dir.is_dir():
            raise DeviceError(f"no PWM chip at {self.chip_dir} (is the PWM overlay enabled?)")
        npwm = _read_int(self.chip_dir / "npwm")
        if not 0 <= self.channel < npwm:
            raise DeviceError(f"{self.chip_dir} has {npwm} channels, no channel {self.channel}")
        if not self.dir.is_dir():
            _write(self.chip_dir / "export", self.channel)
            self._exported_here = True
        deadline = time.monotonic() + self.export_timeout_s
        while True:
            try:
                _write(self.dir / "enable", 0)
                break
            except OSError as err:  # not there yet, or not yet writable (udev)
                if time.monotonic() > deadline:
                    raise DeviceError(f"{self.dir} did not become writable after export: {err}") from err
                time.sleep(0.01)
        self.period_ns = _read_int(self.dir / "period")

    def set_period_ns(self, period_ns: int) -> None:
        """Set the period (ns, > 0), lowering the duty cycle first if it would exceed it."""
        if period_ns <= 0:
            raise ValueError(f"period_ns: must be > 0, got {period_ns}")
        if _read_int(self.dir / "duty_cycle") > period_ns:
            _write(self.dir / "duty_cycle", 0)
        _write(self.dir / "period", period_ns)
        self.period_ns = period_ns

    def set_duty_ns(self, duty_ns: int) -> None:
        """Set the duty cycle (ns, 0..period)."""
        if not 0 <= duty_ns <= self.period_ns:
            raise ValueError(f"duty_ns: must be in [0, {self.period_ns}], got {duty_ns}")
        _write(self.dir / "duty_cycle", duty_ns)

    def set_duty(self, duty: float) -> None:
        """Set the duty cycle as a fraction (0..1) of the period."""
        if not 0.0 <= duty <= 1.0:
            raise ValueError(f"duty: must be in [0, 1], got {duty}")
        self.set_duty_ns(round(duty * self.period_ns))

    def read_duty(self) -> float:
        """The duty cycle as a fraction of the period (0 when disabled)."""
        if _read_int(self.dir / "enable") == 0 or self.period_ns == 0:
            return 0.0
        return _read_int(self.dir / "duty_cycle") / self.period_ns

    def set_enabled(self, enabled: bool) -> None:
        """Start (True) or stop (False) the output."""
        _write(self.dir / "enable", 1 if enabled else 0)

    def close(self, unexport: bool = True) -> None:
        """Duty 0 and disabled; unexport if this object exported the channel and `unexport` is set."""
        try:
            _write(self.dir / "duty_cycle", 0)
        finally:
            _write(self.dir / "enable", 0)
            if unexport and self._exported_here:
                _write(self.chip_dir / "unexport", self.channel)
                self._exported_here = False


class SysfsPwmGroup:
    """Channels of one sysfs PWM chip, addressed by channel number like the PCA9685's.

    Args:
        root: the pwm class directory (/sys/class/pwm on the rig).
        chip: N of pwmchipN.
        channels: the channel numbers used.
    """

    def __init__(self, root: Path, chip: int, channels: Sequence[int]) -> None:
        self._channels = {c: SysfsPwmChannel(root, chip, c) for c in channels}

    def configure(self, frequency_hz: float) -> float:
        """Export every channel, set its period, duty 0, enabled. Returns the frequency obtained (Hz).

        Raises:
            DeviceError: a channel could not be exported.
            OSError: a sysfs write failed.
        """
        period_ns = round(1e9 / frequency_hz)
        for ch in self._channels.values():
            ch.open()
            ch.set_period_ns(period_ns)
            ch.set_duty_ns(0)
            ch.set_enabled(True)
        return 1e9 / period_ns

    def set_duty(self, channel: int, duty: float) -> None:
        """Set one channel's duty cycle (0..1)."""
        self._channels[channel].set_duty(duty)

    def read_duty(self, channel: int) -> float:
        """Read back one channel's duty cycle (0..1)."""
        return self._channels[channel].read_duty()

    def all_off(self) -> None:
        """Every channel at duty 0 (still enabled: the output is held low)."""
        errors: list[OSError] = []
        for ch in self._channels.values():
            try:
                ch.set_duty_ns(0)
            except OSError as err:
                errors.append(err)
        if errors:
            raise errors[0]

    def close(self) -> None:
        """Every channel at duty 0, disabled and unexported (if this group exported it)."""
        for ch in self._channels.values():
            ch.close()
