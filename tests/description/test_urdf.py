"""The leg's URDF: read back exactly, bad documents named by source and element, the packaged one."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

import pytest
import yaml

from g2p.description import Joint, LegDescription
from g2p.description.urdf import (
    ROBOT_NAME,
    UrdfError,
    leg_urdf,
    load_leg_description,
    packaged_leg_description,
    packaged_urdf_path,
    parse_leg_urdf,
)
from tests.description.test_leg import LEG

# Floats with no short decimal form: written with repr, they still come back bit for bit.
AWKWARD = replace(
    LEG,
    hip_height_m=0.1 + 0.2 + 0.3,
    thigh=replace(LEG.thigh, length_m=1 / 3, com_m=(1e-17, -1 / 6), inertia_kg_m2=2.0**-30),
    joints=(Joint("proximal", -math.pi / 3, math.pi / 7), Joint("distal", -math.e / 2, 0.0)),
    belt_half_width_m=math.sqrt(2) / 10,
    pad_half_length_m=1 / 30,
)


@pytest.mark.parametrize("description", [LEG, AWKWARD], ids=["round", "awkward"])
def test_round_trip_is_exact(description: LegDescription) -> None:
    assert parse_leg_urdf(leg_urdf(description)) == description


def test_the_tree_is_treadmill_carriage_thigh_shank_foot_with_two_sensed_joints() -> None:
    robot = ET.fromstring(leg_urdf(LEG))
    assert robot.get("name") == ROBOT_NAME
    tree = {
        j.get("name"): (j.get("type"), j.find("parent").get("link"), j.find("child").get("link"))
        for j in robot.iter("joint")
    }
    assert tree == {
        "carriage": ("fixed", "treadmill", "carriage"),
        "proximal": ("revolute", "carriage", "thigh"),
        "distal": ("revolute", "thigh", "shank"),
        "ankle": ("fixed", "shank", "foot"),
    }
    assert {link.get("name") for link in robot.iter("link")} == {
        "treadmill",
        "carriage",
        "thigh",
        "shank",
        "foot",
    }
    # The hip height, the link lengths and the limits, as written.
    origins = {j.get("name"): j.find("origin").get("xyz") for j in robot.iter("joint")}
    assert origins == {
        "carriage": "0.0 0.0 1.0",
        "proximal": "0.0 0.0 0.0",
        "distal": "0.0 0.0 -0.3",
        "ankle": "0.0 0.0 -0.2",
    }
    limit = robot.find("joint[@name='distal']/limit")
    assert limit is not None and (limit.get("lower"), limit.get("upper")) == ("-1.5", "0.0")
    inertia = robot.find("link[@name='thigh']/inertial/inertia")
    assert inertia is not None and inertia.get("iyy") == inertia.get("ixx") == inertia.get("izz") == "0.003"


def test_the_packaged_urdf_is_the_packaged_leg_at_the_treadmill_height() -> None:
    leg = packaged_leg_description()
    assert leg.hip_height_m == 0.42
    assert (leg.thigh.length_m, leg.shank.length_m) == (0.2, 0.2)
    assert leg.reach_m == pytest.approx(0.437)
    assert [(j.name, math.degrees(j.lower_rad), math.degrees(j.upper_rad)) for j in leg.joints] == [
        ("proximal", pytest.approx(-55.0), pytest.approx(55.0)),
        ("distal", pytest.approx(-100.0), 0.0),
    ]
    assert load_leg_description(packaged_urdf_path()) == leg


@pytest.mark.parametrize("description", [LEG, AWKWARD], ids=["round", "awkward"])
def test_the_text_survives_a_ros_parameter_on_the_command_line(description: LegDescription) -> None:
    """`-p robot_description:="$(cat leg.urdf)"` reads the value as YAML: it must be one string (folded)."""
    value = yaml.safe_load(leg_urdf(description))
    assert isinstance(value, str)
    assert parse_leg_urdf(value) == description


def test_extra_elements_are_ignored() -> None:
    robot = ET.fromstring(leg_urdf(LEG))
    thigh = robot.find("link[@name='thigh']")
    assert thigh is not None
    ET.SubElement(ET.SubElement(ET.SubElement(thigh, "visual"), "geometry"), "mesh", filename="thigh.stl")
    ET.SubElement(robot, "gazebo")
    assert parse_leg_urdf(ET.tostring(robot, encoding="unicode")) == LEG


def _edit(path: str, attribute: str | None = None, value: str | None = None) -> str:
    """The URDF of LEG with the element at `path` removed, or its `attribute` set to `value`."""
    robot = ET.fromstring(leg_urdf(LEG))
    element = robot.find(path)
    assert element is not None, path
    if attribute is None:
        parent = robot.find(f"{path}/..")
        assert parent is not None
        parent.remove(element)
    else:
        assert value is not None
        element.set(attribute, value)
    return ET.tostring(robot, encoding="unicode")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("<robot", "not XML"),
        ("<model name='g2p_leg'/>", "root element must be <robot>"),
        (_edit("joint[@name='distal']"), "no <joint name='distal'>"),
        (_edit("link[@name='shank']"), "no <link name='shank'>"),
        (_edit("joint[@name='proximal']/limit"), "joint 'proximal' has no <limit>"),
        (_edit("joint[@name='proximal']/limit", "upper", "wide"), "joint 'proximal' limit: upper='wide'"),
        (_edit("joint[@name='distal']/limit", "lower", "nan"), "is not 1 finite number"),
        (_edit("joint[@name='distal']/axis", "xyz", "0 1 0"), "axis must be '0 -1 0'"),
        (_edit("joint[@name='distal']", "type", "continuous"), "must be of type 'revolute'"),
        (
            _edit("joint[@name='ankle']/parent", "link", "thigh"),
            "joint 'ankle' must have parent link 'shank'",
        ),
        (_edit("joint[@name='distal']/origin", "xyz", "0.1 0 -0.3"), "straight below its parent"),
        (_edit("joint[@name='carriage']/origin", "xyz", "0 0"), "xyz='0 0' is not 3 finite"),
        (_edit("link[@name='foot']/inertial/mass"), "link 'foot' inertial has no <mass>"),
        (_edit("link[@name='foot']/inertial/inertia", "iyy", "x"), "link 'foot' inertia: iyy='x'"),
        (_edit("link[@name='foot']/visual[@name='pad']"), "link 'foot' has no <visual name='pad'>"),
        (_edit("link[@name='treadmill']/visual/geometry/box"), "visual 'belt' has no <geometry/box>"),
        (_edit("link[@name='thigh']/inertial/mass", "value", "-0.4"), "invalid leg: .*non-negative"),
        (_edit("joint[@name='carriage']/origin", "xyz", "0 0 -1"), "invalid leg"),
    ],
)
def test_bad_documents_raise_naming_the_source_and_the_element(text: str, message: str) -> None:
    with pytest.raises(UrdfError, match=message) as caught:
        parse_leg_urdf(text, source="/leg/robot_description")
    assert isinstance(caught.value, ValueError)
    assert str(caught.value).startswith("/leg/robot_description: ")


def test_a_file_error_names_the_file(tmp_path: Path) -> None:
    path = tmp_path / "leg.urdf"
    path.write_text(_edit("joint[@name='ankle']"))
    with pytest.raises(UrdfError, match=f"^{path}: no <joint name='ankle'>"):
        load_leg_description(path)
