"""Hardware plants on physics-backed fake buses, shared by the hardware tests and the conformance suite."""

from __future__ import annotations

from g2p.hardware import HardwareLeg, HardwareLegConfig, SimulatedClock, WiringConfig
from g2p.hardware_fake.buses import FakeBuses, FakeBusesConfig, fake_devices

# The watchdog thread reads the clock; with a simulated clock, time only moves inside ticks, so it
# would never trip: leave it off and test it on the monotonic clock.
FAST = HardwareLegConfig(step_watchdog_s=0.0)


def fake_leg(
    wiring: WiringConfig | None = None,
    config: HardwareLegConfig = FAST,
    fake_config: FakeBusesConfig | None = None,
) -> tuple[HardwareLeg, FakeBuses]:
    """A HardwareLeg on fake buses backed by the MuJoCo leg (air by default), on a simulated clock."""
    wiring = wiring if wiring is not None else WiringConfig()
    fake, devices = fake_devices(wiring, fake_config, SimulatedClock())
    return HardwareLeg(devices, wiring, config, fake.clock), fake


def hardware_leg_on_fake_buses() -> HardwareLeg:
    """The conformance suite's factory: the hardware plant, chips answering byte for byte, foot in the air."""
    return fake_leg()[0]


class RecordingSpi:
    """An SPI device wrapper that records every transfer (bytes out, bytes in)."""

    def __init__(self, device: object) -> None:
        self.device = device
        self.sent: list[list[int]] = []
        self.received: list[list[int]] = []

    def xfer2(self, data: list[int]) -> list[int]:
        self.sent.append(list(data))
        rx = self.device.xfer2(list(data))  # type: ignore[attr-defined]
        self.received.append(list(rx))
        return rx

    def close(self) -> None:
        pass


class RecordingChip:
    """An I2C chip wrapper recording the bytes of every write and read transaction on the wire."""

    def __init__(self, chip: object) -> None:
        self.chip = chip
        self.faults = chip.faults  # type: ignore[attr-defined]
        self.wire: list[tuple[str, list[int]]] = []

    def write(self, data: list[int]) -> None:
        self.wire.append(("w", list(data)))
        self.chip.write(data)  # type: ignore[attr-defined]

    def read(self, length: int) -> list[int]:
        out = self.chip.read(length)  # type: ignore[attr-defined]
        self.wire.append(("r", list(out)))
        return out  # type: ignore[no-any-return]
