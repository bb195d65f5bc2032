"""sysfs PWM against a directory tree whose fake kernel exports channels as /sys/class/pwm does."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from g2p.hardware.errors import DeviceError
from g2p.hardware.sysfs_pwm import SysfsPwmChannel, SysfsPwmGroup
from g2p.hardware_fake.chips import FakePwmSysfs


@pytest.fixture
def chip(tmp_path: Path) -> Iterator[FakePwmSysfs]:
    fake = FakePwmSysfs(tmp_path, chip=0, npwm=4)
    yield fake
    fake.close()


def test_open_exports_and_close_unexports(chip: FakePwmSysfs) -> None:
    channel = SysfsPwmChannel(chip.root, 0, 2)
    assert not chip.channel_dir(2).exists()
    channel.open()
    assert chip.channel_dir(2).is_dir()
    channel.set_period_ns(1_000_000)
    channel.set_duty(0.25)
    channel.set_enabled(True)
    assert chip.channel_state(2) == (1_000_000, 250_000, True)
    assert chip.output_duty(2) == 0.25 and channel.read_duty() == 0.25
    channel.close()
    assert chip.output_duty(2) == 0.0
    SysfsPwmChannel(chip.root, 0, 2)  # still constructible
    for _ in range(200):
        if not chip.channel_dir(2).exists():
            break
        import time

        time.sleep(0.005)
    assert not chip.channel_dir(2).exists()


def test_an_already_exported_channel_is_reused_and_left_exported(chip: FakePwmSysfs) -> None:
    chip.export(1)
    channel = SysfsPwmChannel(chip.root, 0, 1)
    channel.open()
    channel.set_period_ns(500_000)
    channel.close()
    assert chip.channel_dir(1).is_dir()


def test_a_shorter_period_lowers_the_duty_first_and_duty_is_bounded(chip: FakePwmSysfs) -> None:
    channel = SysfsPwmChannel(chip.root, 0, 0)
    channel.open()
    channel.set_period_ns(1_000_000)
    channel.set_duty_ns(900_000)
    channel.set_period_ns(500_000)  # the kernel would refuse a period below the duty cycle
    assert chip.channel_state(0)[:2] == (500_000, 0)
    with pytest.raises(ValueError):
        channel.set_duty_ns(600_000)


def test_missing_chip_or_channel_or_export_timeout(tmp_path: Path, chip: FakePwmSysfs) -> None:
    with pytest.raises(DeviceError, match="no PWM chip"):
        SysfsPwmChannel(chip.root, 7, 0).open()
    with pytest.raises(DeviceError, match="4 channels"):
        SysfsPwmChannel(chip.root, 0, 4).open()
    dead = FakePwmSysfs(tmp_path / "dead", 0, 2)
    dead.close()  # no kernel: the channel never appears
    with pytest.raises(DeviceError, match="did not become writable"):
        SysfsPwmChannel(dead.root, 0, 0, export_timeout_s=0.05).open()


def test_group_configures_every_channel_and_switches_them_off(chip: FakePwmSysfs) -> None:
    group = SysfsPwmGroup(chip.root, 0, (0, 1, 3))
    assert group.configure(1000.0) == pytest.approx(1000.0)
    group.set_duty(3, 0.5)
    assert chip.output_duty(3) == 0.5 and group.read_duty(3) == 0.5
    group.all_off()
    assert [chip.output_duty(c) for c in (0, 1, 3)] == [0.0, 0.0, 0.0]
    group.close()
