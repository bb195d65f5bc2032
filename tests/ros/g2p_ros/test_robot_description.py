"""`robot_description` from the installed rig executables: the leg's URDF, latched, for late subscribers.

The simulator describes the very model it runs, the driver the MuJoCo leg behind its fake buses or, on the
Pi, the packaged URDF or its `description_file`; the recorder keeps the message in the bag.
"""

from __future__ import annotations

import signal
import subprocess
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import pytest
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
from std_msgs.msg import String

from g2p.bags import BagReader
from g2p.description.urdf import leg_urdf, packaged_leg_description, packaged_urdf_path, parse_leg_urdf
from g2p.hardware_fake.buses import FakeBusesConfig, fake_leg_config
from g2p.sim import MujocoLegConfig
from g2p.sim.config import TREADMILL_CARRIAGE_HEIGHT_M, packaged_model_path
from g2p.sim.model_description import config_description
from g2p_ros import contract
from tests.ros.rig_nodes import start_driver, start_sim
from tests.ros.rosproc import NodeProcess, RosPeer, executable, wait_until

TOPIC = "/leg/robot_description"


class DescriptionPeer(RosPeer):
    """Subscribes to robot_description only when told to: a late subscriber."""

    def __init__(self) -> None:
        super().__init__("description_peer")
        self.received: list[str] = []
        self.start()

    def wait_for_publisher(self, node_name: str) -> None:
        wait_until(
            lambda: any(i.node_name == node_name for i in self.node.get_publishers_info_by_topic(TOPIC)),
            30.0,
            f"{node_name}'s robot_description publisher",
        )

    def subscribe_and_receive(self) -> str:
        """Subscribe now and return the one latched message."""
        self.node.create_subscription(
            String,
            contract.ROBOT_DESCRIPTION,
            lambda m: self.received.append(m.data),
            contract.DESCRIPTION_QOS,
        )
        wait_until(lambda: len(self.received) == 1, 30.0, "the latched robot_description")
        (info,) = self.node.get_publishers_info_by_topic(TOPIC)
        assert info.qos_profile.reliability == ReliabilityPolicy.RELIABLE
        assert info.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
        return self.received[0]


@pytest.fixture
def peer() -> Iterator[DescriptionPeer]:
    p = DescriptionPeer()
    yield p
    p.close()


def test_a_late_subscriber_gets_the_description_of_the_model_the_sim_runs(
    tmp_path: Path, peer: DescriptionPeer
) -> None:
    # A custom model (a 0.25 m thigh) with the carriage raised: the description follows both.
    model = tmp_path / "leg.xml"
    xml = packaged_model_path().read_text()
    model.write_text(xml.replace('name="shank" pos="0 0 -0.2"', 'name="shank" pos="0 0 -0.25"'))
    sim = start_sim(tmp_path, "time_mode:=fast", f"leg.model_path:={model}", "leg.carriage_height_m:=0.6")
    try:
        peer.wait_for_publisher("sim")
        wait_until(lambda: "serving the rig contract" in sim.log(), 30.0, "the sim to be up")  # published
        text = peer.subscribe_and_receive()
    finally:
        assert sim.stop() == 0, sim.log()
    leg = parse_leg_urdf(text, TOPIC)
    assert (leg.hip_height_m, leg.thigh.length_m, leg.shank.length_m) == (0.6, 0.25, 0.2)
    assert text == leg_urdf(config_description(MujocoLegConfig(model_path=str(model), carriage_height_m=0.6)))


def test_the_driver_on_fake_devices_describes_its_mujoco_leg_before_any_transition(
    tmp_path: Path, peer: DescriptionPeer
) -> None:
    driver = start_driver(
        tmp_path, tmp_path / "fake_rig", f"fake.carriage_height_m:={TREADMILL_CARRIAGE_HEIGHT_M}"
    )
    try:
        peer.wait_for_publisher("driver")
        text = peer.subscribe_and_receive()
    finally:
        assert driver.stop() == 0, driver.log()
    assert text == leg_urdf(config_description(fake_leg_config(FakeBusesConfig(carriage_height_m=0.42))))
    # The packaged leg at the treadmill height: the shipped URDF, to the byte.
    assert text == packaged_urdf_path().read_text()


@pytest.mark.parametrize("custom", [False, True], ids=["packaged", "description_file"])
def test_the_driver_on_the_pi_publishes_the_packaged_urdf_or_its_description_file(
    custom: bool, tmp_path: Path, peer: DescriptionPeer
) -> None:
    expected = packaged_urdf_path().read_text()
    args = ["--ros-args"]  # no fake devices: the Pi's driver, which opens no device until configured
    if custom:
        # A leg on a lower carriage, with an element of the user's own: published as the file is.
        expected = leg_urdf(replace(packaged_leg_description(), hip_height_m=0.5))
        expected = expected.replace("</robot>", '  <link name="camera" />\n</robot>')
        (tmp_path / "leg.urdf").write_text(expected)
        args += ["-p", f"description_file:={tmp_path / 'leg.urdf'}"]
    driver = NodeProcess("g2p_driver", "driver", args, tmp_path)
    try:
        peer.wait_for_publisher("driver")
        text = peer.subscribe_and_receive()
    finally:
        assert driver.stop() == 0, driver.log()
    assert text == expected
    assert parse_leg_urdf(text).hip_height_m == (0.5 if custom else 0.42)


def test_a_description_file_that_is_not_the_leg_stops_the_driver_naming_it(tmp_path: Path) -> None:
    path = tmp_path / "leg.urdf"
    path.write_text(packaged_urdf_path().read_text().replace('name="distal"', 'name="knee"'))
    done = subprocess.run(
        [str(executable("g2p_driver", "driver")), "--ros-args", "-p", f"description_file:={path}"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2, done.stderr
    assert f"invalid parameter description_file: {path}: no <joint name='distal'>" in done.stderr
    assert "Traceback" not in done.stderr


def test_the_recorder_keeps_the_description_in_the_bag(tmp_path: Path) -> None:
    sim = start_sim(tmp_path)  # real time: it ticks all along, so the recorder drains for its full timeout
    bags = tmp_path / "bags"
    recorder = NodeProcess("g2p_recorder", "record", ["--ros-args", "-p", f"bags_dir:={bags}"], tmp_path)
    try:
        wait_until(lambda: f"recording {TOPIC}" in recorder.log(), 60.0, "the recorder to subscribe")
        assert "transient local" in recorder.log().split(f"recording {TOPIC}")[1].splitlines()[0]
        assert recorder.stop(signal.SIGINT) == 0, recorder.log()
    finally:
        assert sim.stop() == 0, sim.log()
    (bag,) = bags.iterdir()
    with BagReader(bag) as reader:
        (message,) = list(reader.messages([TOPIC]))
    assert message.msg.data == packaged_urdf_path().read_text()
