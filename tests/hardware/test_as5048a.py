"""AS5048A framing against a fake chip that answers with the datasheet's frames."""

from __future__ import annotations

import math

import pytest

from g2p.hardware import as5048a as enc
from g2p.hardware.as5048a import AS5048A, EncoderModel
from g2p.hardware.errors import EncoderErrorFlag, EncoderParityError
from g2p.hardware_fake.chips import FakeAS5048A, FaultKind
from tests.hardware.fake_legs import RecordingSpi


def test_command_frames_have_the_datasheet_values() -> None:
    assert enc.READ_ANGLE == 0xFFFF  # address 0x3FFF, read, parity 1
    assert enc.CLEAR_ERROR == 0x4001  # address 0x0001, read, parity 0
    assert enc.NOP == 0xC000
    assert enc.command_frame(0x3FFD) == 0x7FFD  # 14 ones: even already
    assert enc.command_frame(0x0016, read=False) == 0x0016 | 0x8000  # 3 ones: parity bit set
    with pytest.raises(ValueError):
        enc.command_frame(0x4000)


def test_read_sends_command_then_nop_and_takes_the_pipelined_answer() -> None:
    spi = RecordingSpi(FakeAS5048A(lambda: 0x1234))
    assert AS5048A(spi).read_raw() == 0x1234
    assert spi.sent == [[0xFF, 0xFF], [0xC0, 0x00]]
    # 0x1234 has 5 ones: the parity bit makes the frame even.
    assert spi.received[1] == [0x92, 0x34]


def test_angle_applies_zero_offset_direction_and_wraps_to_plus_minus_pi() -> None:
    raw = [0]
    device = AS5048A(FakeAS5048A(lambda: raw[0]), zero_offset_counts=16000, direction=1)
    raw[0] = 16000
    assert device.read_angle_rad() == 0.0
    raw[0] = 100  # 484 counts past the zero, across the wrap
    assert device.read_angle_rad() == pytest.approx(484 * 2 * math.pi / 16384)
    raw[0] = 16000 - 4096
    assert device.read_angle_rad() == pytest.approx(-math.pi / 2)
    flipped = AS5048A(FakeAS5048A(lambda: raw[0]), zero_offset_counts=16000, direction=-1)
    assert flipped.read_angle_rad() == pytest.approx(math.pi / 2)


def test_parity_error_is_detected_and_counted() -> None:
    chip = FakeAS5048A(lambda: 1000)
    device = AS5048A(chip)
    chip.faults.set(FaultKind.ENCODER_PARITY, 2)  # the command's answer and the NOP's answer
    with pytest.raises(EncoderParityError):
        device.read_raw()
    assert device.counters.parity_errors == 1
    assert device.read_raw() == 1000  # the next read is clean


def test_error_flag_raises_with_the_error_bits_and_is_cleared_by_reading_them() -> None:
    chip = FakeAS5048A(lambda: 1000)
    device = AS5048A(chip)
    chip.faults.set(FaultKind.ENCODER_ERROR_FLAG, 1)
    with pytest.raises(EncoderErrorFlag) as info:
        device.read_raw()
    assert info.value.error_bits == enc.ERROR_FRAMING
    assert device.counters.error_flags == 1
    assert device.read_raw() == 1000


def test_a_command_with_bad_parity_makes_the_chip_flag_a_parity_error() -> None:
    chip = FakeAS5048A(lambda: 5)
    chip.xfer2([0x7F, 0xFF])  # read angle without its parity bit
    device = AS5048A(chip)
    with pytest.raises(EncoderErrorFlag) as info:
        device.read_raw()
    assert info.value.error_bits & enc.ERROR_PARITY


def test_wrong_spi_mode_is_caught_by_the_parity_check_or_the_error_flag() -> None:
    chip = FakeAS5048A(lambda: 0x1234)
    chip.mode = 0  # the AS5048A needs mode 1
    with pytest.raises((EncoderParityError, EncoderErrorFlag)):
        AS5048A(chip).read_raw()


@pytest.mark.parametrize("model", list(EncoderModel))
def test_magnet_diagnostics(model: EncoderModel) -> None:
    chip = FakeAS5048A(lambda: 0, model)
    device = AS5048A(chip, model=model)
    status = device.read_magnet()
    assert status.ok and status.agc == 0x80
    chip.diagnostics = 0x100 | 0x800 | 0xFF  # field too weak, AGC at its maximum
    status = device.read_magnet()
    assert status.too_weak and not status.ok


def test_invalid_construction_arguments() -> None:
    with pytest.raises(ValueError, match="zero_offset_counts"):
        AS5048A(FakeAS5048A(lambda: 0), zero_offset_counts=16384)
    with pytest.raises(ValueError, match="direction"):
        AS5048A(FakeAS5048A(lambda: 0), direction=0)
