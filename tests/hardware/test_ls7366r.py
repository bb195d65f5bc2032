"""LS7366R instruction bytes and counts, and the belt odometer, against a fake counter."""

from __future__ import annotations

import math

import pytest

from g2p.hardware.errors import DeviceError
from g2p.hardware.ls7366r import LS7366R, BeltOdometer, to_signed32
from g2p.hardware_fake.chips import FakeLS7366R, FloatingSpi
from tests.hardware.fake_legs import RecordingSpi


def test_configure_writes_and_reads_back_the_mode_registers_then_clears() -> None:
    chip = FakeLS7366R(lambda: 0)
    spi = RecordingSpi(chip)
    LS7366R(spi).configure(4)
    assert spi.sent == [[0x88, 0x03], [0x90, 0x00], [0x48, 0], [0x50, 0], [0x20], [0x30]]
    assert chip.mdr0 == 0x03 and chip.mdr1 == 0x00


def test_count_is_latched_into_otr_and_read_msb_first() -> None:
    edges = [0]
    chip = FakeLS7366R(lambda: edges[0])
    spi = RecordingSpi(chip)
    counter = LS7366R(spi)
    counter.configure(4)
    edges[0] = 0x01020304
    spi.sent.clear()
    spi.received.clear()
    assert counter.read_count() == 0x01020304
    assert spi.sent == [[0xE8], [0x68, 0, 0, 0, 0]]
    assert spi.received[1] == [0, 0x01, 0x02, 0x03, 0x04]
    edges[0] = -5
    assert counter.read_count() == -5


def test_configure_clears_the_count_and_x1_divides_the_edges() -> None:
    edges = [1000]
    chip = FakeLS7366R(lambda: edges[0])
    counter = LS7366R(chip)
    counter.configure(1)
    assert counter.read_count() == 0
    edges[0] += 400
    assert counter.read_count() == 100
    assert counter.read_status() & 0x08  # counting enabled


def test_absent_chip_fails_configure_with_a_named_error() -> None:
    with pytest.raises(DeviceError, match=r"belt counter.*MDR0=0xff"):
        LS7366R(FloatingSpi(), name="belt counter").configure()


def test_signed32() -> None:
    assert to_signed32(0xFFFFFFFF) == -1
    assert to_signed32(0x7FFFFFFF) == 2**31 - 1
    assert to_signed32(2**32 + 3) == 3


def test_odometer_is_cumulative_across_the_32_bit_wrap() -> None:
    odo = BeltOdometer(counts_per_rev=4096, drum_radius_mm=25.0, direction=1)
    mm_per_count = 2 * math.pi * 25.0 / 4096
    assert odo.update(2**31 - 10) == 0.0  # the first reading is the origin
    assert odo.update(to_signed32(2**31 + 10)) == pytest.approx(20 * mm_per_count)
    assert odo.update(2**31 - 30) == pytest.approx(-20 * mm_per_count)
    reverse = BeltOdometer(4096, 25.0, -1)
    reverse.update(0)
    assert reverse.update(4096) == pytest.approx(-2 * math.pi * 25.0)
