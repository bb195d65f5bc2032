"""The leg as a URDF (`robot_description`): written from a LegDescription, and read back into one.

The rig nodes publish `leg_urdf(description)` latched on `robot_description`, so robot_state_publisher,
RViz or Foxglove draw the leg from `joint_states`; the viewer and the report read it back with
`parse_leg_urdf`. Every float is written with repr, so `parse_leg_urdf(leg_urdf(d)) == d` exactly.
`packaged_leg_description()` reads the URDF shipped in g2p/description/models/leg.urdf (generated from
leg.xml at the treadmill carriage height by `python -m g2p.sim.model_description`), for machines without
MuJoCo.

The tree, in the model's frame (g2p.description: belt surface z = 0, leg facing +x, hinges about -y):

    treadmill --carriage (fixed, hip height)--> carriage --proximal (revolute)--> thigh
              --distal (revolute)--> shank --ankle (fixed)--> foot

The passive ankle is fixed at angle 0: it is not sensed, and joint_states names only proximal and distal,
so robot_state_publisher can publish every link's transform. stdlib and numpy only.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from importlib import resources
from pathlib import Path

from g2p.description.leg import Joint, LegDescription, Link

ROBOT_NAME = "g2p_leg"
ROOT_LINK = "treadmill"
# URDF requires effort and velocity on a revolute joint's limit; nothing in the rig reads them. Effort:
# the largest torque a tendon puts on a joint (60 N at full activation on M1's 50 mm hip arm, leg.xml).
# Velocity: well above what babbling reaches (about 10 rad/s), so no tool clamps a recorded motion.
JOINT_EFFORT_NM = 3.0
JOINT_VELOCITY_RAD_S = 30.0
# The belt is drawn this long (m): longer than the foot's reach either side of the hip (0.437 m).
BELT_HALF_LENGTH_M = 0.5
BELT_THICKNESS_M = 0.02
_AXIS = "0 -1 0"
_COLOURS = {"leg": "0.7 0.7 0.75 1", "pad": "0.1 0.1 0.1 1", "belt": "0.15 0.15 0.15 1"}
# Visual names the parser finds the sizes by.
_PAD = "pad"
_BELT = "belt"


class UrdfError(ValueError):
    """A URDF is not a leg description: an element is missing, or a value is invalid."""


def _f(value: float) -> str:
    """A float as its shortest exact text (repr of a Python float, also for numpy scalars); -0.0 as 0.0."""
    return repr(float(value) + 0.0)


def _xyz(x: float, y: float, z: float) -> str:
    return f"{_f(x)} {_f(y)} {_f(z)}"


def _origin(parent: ET.Element, xyz: str, rpy: str = "0 0 0") -> None:
    ET.SubElement(parent, "origin", xyz=xyz, rpy=rpy)


def _visual(
    link: ET.Element,
    name: str,
    colour: str,
    shape: str,
    size: dict[str, str],
    x: float,
    z: float,
    rpy: str = "0 0 0",
) -> None:
    """A visual of `shape` with attributes `size`, centred at (x, 0, z) in the link's frame (m)."""
    visual = ET.SubElement(link, "visual", name=name)
    _origin(visual, _xyz(x, 0.0, z), rpy)
    ET.SubElement(ET.SubElement(visual, "geometry"), shape, attrib=size)
    ET.SubElement(visual, "material", name=colour)


def _inertial(element: ET.Element, link: Link) -> None:
    """The link's mass, centre of mass and inertia.

    The description holds only the moment about the hinge axis (y). It goes on iyy, and on ixx and izz too:
    the leg never turns about x or z, and an isotropic tensor is always a valid one (positive, triangle
    inequality), which a tensor with zeros there would not be for every tool.
    """
    inertial = ET.SubElement(element, "inertial")
    _origin(inertial, _xyz(link.com_m[0], 0.0, link.com_m[1]))
    ET.SubElement(inertial, "mass", value=_f(link.mass_kg))
    i = _f(link.inertia_kg_m2)
    ET.SubElement(inertial, "inertia", ixx=i, ixy="0", ixz="0", iyy=i, iyz="0", izz=i)


def _limb(robot: ET.Element, link: Link) -> None:
    """Thigh or shank: a cylinder from its joint down to the next."""
    element = ET.SubElement(robot, "link", name=link.name)
    size = {"radius": _f(link.radius_m), "length": _f(link.length_m)}
    _visual(element, link.name, "leg", "cylinder", size, 0.0, -link.length_m / 2)
    _inertial(element, link)


def _foot(robot: ET.Element, foot: Link, pad_half_length_m: float) -> None:
    """The foot: a bracket down from the ankle and the pad, a capsule along x (a cylinder and two spheres)."""
    element = ET.SubElement(robot, "link", name=foot.name)
    if foot.length_m > 0.0:
        size = {"radius": _f(foot.radius_m / 2), "length": _f(foot.length_m)}
        _visual(element, "bracket", "leg", "cylinder", size, 0.0, -foot.length_m / 2)
    pad = {"radius": _f(foot.radius_m), "length": _f(2 * pad_half_length_m)}
    # rpy turns the cylinder's axis (z) onto x.
    _visual(element, _PAD, "pad", "cylinder", pad, 0.0, -foot.length_m, rpy=f"0 {_f(math.pi / 2)} 0")
    for end, x in (("pad_front", pad_half_length_m), ("pad_back", -pad_half_length_m)):
        _visual(element, end, "pad", "sphere", {"radius": _f(foot.radius_m)}, x, -foot.length_m)
    _inertial(element, foot)


def _joint(robot: ET.Element, name: str, kind: str, parent: str, child: str, xyz: str) -> ET.Element:
    joint = ET.SubElement(robot, "joint", name=name, type=kind)
    _origin(joint, xyz)
    ET.SubElement(joint, "parent", link=parent)
    ET.SubElement(joint, "child", link=child)
    return joint


def _hinge(robot: ET.Element, joint: Joint, parent: str, child: str, below_m: float) -> None:
    element = _joint(robot, joint.name, "revolute", parent, child, _xyz(0.0, 0.0, -below_m))
    ET.SubElement(element, "axis", xyz=_AXIS)
    ET.SubElement(
        element,
        "limit",
        lower=_f(joint.lower_rad),
        upper=_f(joint.upper_rad),
        effort=_f(JOINT_EFFORT_NM),
        velocity=_f(JOINT_VELOCITY_RAD_S),
    )


def leg_urdf(description: LegDescription) -> str:
    """The URDF of the leg, robot "g2p_leg", rooted at the belt surface frame `treadmill`.

    Lengths in m, angles in rad, masses in kg, inertias in kg m^2; floats are written exactly (repr).
    Joint origins carry the link lengths (the thigh's is the distal joint's offset, the shank's the
    ankle's); the foot's length is the pad visual's depth below the ankle.
    """
    d = description
    robot = ET.Element("robot", name=ROBOT_NAME)
    # No ": " or " #" anywhere: the text must read as one YAML string, as `-p robot_description:="$(...)"`
    # hands it to robot_state_publisher.
    robot.append(
        ET.Comment(
            " The G2P leg, generated from its MuJoCo model by g2p.description.urdf.leg_urdf (do not edit)."
            " Regenerate the packaged g2p/description/models/leg.urdf with"
            " python -m g2p.sim.model_description > src/g2p/description/models/leg.urdf "
        )
    )
    for name, rgba in _COLOURS.items():
        ET.SubElement(ET.SubElement(robot, "material", name=name), "color", rgba=rgba)

    treadmill = ET.SubElement(robot, "link", name=ROOT_LINK)
    belt = {"size": _xyz(2 * BELT_HALF_LENGTH_M, 2 * d.belt_half_width_m, BELT_THICKNESS_M)}
    _visual(treadmill, _BELT, "belt", "box", belt, 0.0, -BELT_THICKNESS_M / 2)  # its top is the surface
    ET.SubElement(robot, "link", name="carriage")
    _joint(robot, "carriage", "fixed", ROOT_LINK, "carriage", _xyz(0.0, 0.0, d.hip_height_m))

    proximal, distal = d.joints
    _limb(robot, d.thigh)
    _hinge(robot, proximal, "carriage", d.thigh.name, 0.0)
    _limb(robot, d.shank)
    _hinge(robot, distal, d.thigh.name, d.shank.name, d.thigh.length_m)
    _foot(robot, d.foot, d.pad_half_length_m)
    _joint(robot, "ankle", "fixed", d.shank.name, d.foot.name, _xyz(0.0, 0.0, -d.shank.length_m))

    ET.indent(robot, space="  ")
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n"


class _Reader:
    """Finds the leg's elements in a parsed URDF, raising UrdfError naming the source and the element."""

    def __init__(self, robot: ET.Element, source: str) -> None:
        self.robot = robot
        self.source = source or "<urdf>"

    def error(self, what: str) -> UrdfError:
        return UrdfError(f"{self.source}: {what}")

    def one(self, parent: ET.Element, path: str, where: str) -> ET.Element:
        found = parent.find(path)
        if found is None:
            raise self.error(f"{where} has no <{path}>")
        return found

    def named(self, tag: str, name: str) -> ET.Element:
        found = self.robot.find(f"{tag}[@name='{name}']")
        if found is None:
            raise self.error(f"no <{tag} name={name!r}>")
        return found

    def floats(self, element: ET.Element, attribute: str, count: int, where: str) -> list[float]:
        text = element.get(attribute)
        if text is None:
            raise self.error(f"{where} has no attribute {attribute!r}")
        try:
            values = [float(v) for v in text.split()]
        except ValueError:
            values = []
        if len(values) != count or not all(math.isfinite(v) for v in values):
            raise self.error(f"{where}: {attribute}={text!r} is not {count} finite number(s)")
        return values

    def number(self, element: ET.Element, attribute: str, where: str) -> float:
        return self.floats(element, attribute, 1, where)[0]

    def joint(self, name: str, kind: str, parent: str, child: str) -> ET.Element:
        """The joint `name`, checked to be of `kind` between `parent` and `child`."""
        joint = self.named("joint", name)
        where = f"joint {name!r}"
        if joint.get("type") != kind:
            raise self.error(f"{where} must be of type {kind!r}, is {joint.get('type')!r}")
        for end, link in (("parent", parent), ("child", child)):
            if self.one(joint, end, where).get("link") != link:
                raise self.error(f"{where} must have {end} link {link!r}")
        return joint

    def below(self, joint: ET.Element) -> float:
        """How far a joint's origin lies straight below its parent link's (m); the leg is planar."""
        where = f"joint {joint.get('name')!r}"
        origin = joint.find("origin")
        if origin is None:
            return 0.0  # URDF's default origin: the identity
        x, y, z = self.floats(origin, "xyz", 3, f"{where} origin") if "xyz" in origin.attrib else [0.0] * 3
        rpy = self.floats(origin, "rpy", 3, f"{where} origin") if "rpy" in origin.attrib else [0.0] * 3
        if x != 0.0 or y != 0.0 or any(a != 0.0 for a in rpy):
            raise self.error(f"{where} origin must be straight below its parent (0 0 -length, rpy 0 0 0)")
        return -z

    def hinge(self, name: str, parent: str, child: str) -> tuple[Joint, float]:
        """A revolute joint about -y: its limits (rad) and its depth below the parent (m)."""
        joint = self.joint(name, "revolute", parent, child)
        where = f"joint {name!r}"
        axis = self.floats(self.one(joint, "axis", where), "xyz", 3, f"{where} axis")
        if axis != [0.0, -1.0, 0.0]:
            raise self.error(f"{where} axis must be {_AXIS!r} (the leg is planar), is {axis}")
        limit = self.one(joint, "limit", where)
        lower = self.number(limit, "lower", f"{where} limit")
        upper = self.number(limit, "upper", f"{where} limit")
        return Joint(name, lower, upper), self.below(joint)

    def visual(self, link: ET.Element, name: str, shape: str) -> tuple[ET.Element, ET.Element]:
        """A link's visual `name` of geometry `shape`: (the visual, its shape element)."""
        where = f"link {link.get('name')!r}"
        visual = link.find(f"visual[@name='{name}']")
        if visual is None:
            raise self.error(f"{where} has no <visual name={name!r}>")
        return visual, self.one(visual, f"geometry/{shape}", f"{where} visual {name!r}")

    def link(self, name: str, length_m: float, radius_m: float) -> Link:
        element = self.named("link", name)
        where = f"link {name!r}"
        inertial = self.one(element, "inertial", where)
        com = self.floats(
            self.one(inertial, "origin", f"{where} inertial"), "xyz", 3, f"{where} inertial origin"
        )
        return Link(
            name=name,
            length_m=length_m,
            radius_m=radius_m,
            mass_kg=self.number(self.one(inertial, "mass", f"{where} inertial"), "value", f"{where} mass"),
            com_m=(com[0], com[2]),
            inertia_kg_m2=self.number(
                self.one(inertial, "inertia", f"{where} inertial"), "iyy", f"{where} inertia"
            ),
        )


def parse_leg_urdf(text: str, source: str = "") -> LegDescription:
    """The leg description a URDF written by `leg_urdf` holds.

    Other elements (more visuals, meshes, materials) are ignored, so a hand-extended URDF still reads.

    Args:
        text: the URDF document.
        source: where the text came from (a path, a topic), for error messages.

    Raises:
        UrdfError: (a ValueError) the text is not XML, or lacks an element or value of the leg, or holds an
            invalid one; the message names `source` and the element.
    """
    try:
        robot = ET.fromstring(text)
    except ET.ParseError as err:
        raise UrdfError(f"{source or '<urdf>'}: not XML: {err}") from err
    r = _Reader(robot, source)
    if robot.tag != "robot":
        raise r.error(f"the root element must be <robot>, is <{robot.tag}>")

    belt = r.named("link", ROOT_LINK)
    belt_width = r.floats(r.visual(belt, _BELT, "box")[1], "size", 3, f"link {ROOT_LINK!r} belt box")[1]
    hip_height = -r.below(r.joint("carriage", "fixed", ROOT_LINK, "carriage"))
    proximal, _ = r.hinge("proximal", "carriage", "thigh")
    distal, thigh_length = r.hinge("distal", "thigh", "shank")
    shank_length = r.below(r.joint("ankle", "fixed", "shank", "foot"))

    def radius(link: str, visual: str) -> float:
        shape = r.visual(r.named("link", link), visual, "cylinder")[1]
        return r.number(shape, "radius", f"link {link!r} visual {visual!r}")

    pad_visual, pad_shape = r.visual(r.named("link", "foot"), _PAD, "cylinder")
    pad_where = "link 'foot' visual 'pad'"
    pad_xyz = r.floats(r.one(pad_visual, "origin", pad_where), "xyz", 3, f"{pad_where} origin")
    try:
        return LegDescription(
            hip_height_m=hip_height,
            thigh=r.link("thigh", thigh_length, radius("thigh", "thigh")),
            shank=r.link("shank", shank_length, radius("shank", "shank")),
            foot=r.link("foot", -pad_xyz[2], r.number(pad_shape, "radius", pad_where)),
            pad_half_length_m=r.number(pad_shape, "length", pad_where) / 2,
            joints=(proximal, distal),
            belt_half_width_m=belt_width / 2,
        )
    except ValueError as err:
        raise r.error(f"invalid leg: {err}") from err


def packaged_urdf_path() -> Path:
    """Path of the URDF shipped with the package (g2p/description/models/leg.urdf)."""
    return Path(str(resources.files("g2p.description").joinpath("models", "leg.urdf")))


def read_leg_urdf(path: Path) -> str:
    """The text of a URDF file, checked to describe the leg (see parse_leg_urdf).

    Raises:
        UrdfError: the file does not hold a leg; the message names the file.
        OSError: the file cannot be read.
    """
    text = Path(path).read_text(encoding="utf-8")
    parse_leg_urdf(text, source=str(path))
    return text


def load_leg_description(path: Path) -> LegDescription:
    """The leg description of a URDF file.

    Raises:
        UrdfError: the file does not hold a leg (see parse_leg_urdf); the message names the file.
        OSError: the file cannot be read.
    """
    return parse_leg_urdf(Path(path).read_text(encoding="utf-8"), source=str(path))


def packaged_leg_description() -> LegDescription:
    """The packaged leg (leg.xml at the treadmill carriage height), read from the shipped URDF, no MuJoCo."""
    return load_leg_description(packaged_urdf_path())
