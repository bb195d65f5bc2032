"""The rig's YAML description: the shipped example loads, and every error names its field."""

from __future__ import annotations

from pathlib import Path

import pytest

from g2p.hardware import PwmBackend, WiringConfig, load_wiring, wiring_from_dict
from g2p.hardware.as5048a import EncoderModel
from g2p.validation import ConfigError

EXAMPLE = Path(__file__).resolve().parents[2] / "g2p_driver" / "config" / "wiring.yaml"


def test_the_shipped_example_is_valid_and_matches_the_defaults() -> None:
    wiring = load_wiring(EXAMPLE)
    assert wiring == WiringConfig()
    assert wiring.encoders.distal.spi.chip_select == 1
    assert wiring.encoders.proximal.model is EncoderModel.AS5048A
    assert wiring.pwm.backend is PwmBackend.PCA9685 and wiring.pwm.address == 0x40
    assert wiring.current_sensors.addresses == (0x41, 0x44, 0x45)
    assert wiring.pwm.duty(0.0) == pytest.approx(0.1) and wiring.pwm.duty(1.0) == pytest.approx(0.9)
    assert wiring.pwm.activation(wiring.pwm.duty(0.15)) == pytest.approx(0.15)


@pytest.mark.parametrize(
    ("data", "field"),
    [
        ({"pwm": {"frequncy_hz": 100.0}}, "pwm.frequncy_hz: unknown key"),
        ({"encoders": {"distal": {"direction": 0}}}, "encoders.distal.direction: must be +1 or -1"),
        ({"encoders": {"distal": {"direction": "up"}}}, "encoders.distal.direction: must be an integer"),
        ({"encoders": {"proximal": {"zero_offset_counts": 16384}}}, "encoders.proximal.zero_offset_counts"),
        ({"encoders": {"proximal": {"model": "as5600"}}}, "encoders.proximal.model: must be one of"),
        ({"encoders": {"proximal": {"spi": {"chip_select": 1}}}}, "encoders: the two encoders and the belt"),
        ({"belt": {"quadrature": 3}}, "belt.quadrature"),
        ({"belt": {"drum_radius_mm": -1.0}}, "belt.drum_radius_mm"),
        ({"pwm": {"frequency_hz": 5000.0}}, "pwm.frequency_hz"),
        ({"pwm": {"channels": [0, 1]}}, "pwm.channels: must be a list of 3"),
        ({"pwm": {"channels": [0, 1, 1]}}, "pwm.channels: must be 3 distinct"),
        ({"pwm": {"duty_at_zero": 0.9, "duty_at_full": 0.1}}, "pwm.duty_at_full"),
        ({"pwm": {"backend": "pigpio"}}, "pwm.backend: must be one of"),
        ({"pwm": {"invert": 1}}, "pwm.invert: must be true or false"),
        ({"current_sensors": {"addresses": [0x40, 0x44, 0x45]}}, "current_sensors.addresses"),
        ({"current_sensors": {"shunt_ohm": 0.2}}, "current_sensors.max_current_a"),
        ({"motor_enable": {"line": -1}}, "motor_enable.line"),
        ({"treadmill": {}}, "treadmill: unknown key"),
    ],
)
def test_errors_name_the_field(data: dict[str, object], field: str) -> None:
    with pytest.raises(ConfigError, match=field.replace("(", r"\(").replace("+", r"\+")):
        wiring_from_dict(data)


def test_null_enable_line_and_the_sysfs_backend() -> None:
    wiring = wiring_from_dict(
        {"motor_enable": None, "pwm": {"backend": "sysfs", "channels": [0, 1, 2], "frequency_hz": 20000.0}}
    )
    assert wiring.motor_enable is None and wiring.pwm.backend is PwmBackend.SYSFS


def test_unreadable_or_malformed_files(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read"):
        load_wiring(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("pwm: [1, 2\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_wiring(bad)
    bad.write_text("- 1\n")
    with pytest.raises(ConfigError, match="mapping"):
        load_wiring(bad)
