"""A rig node's `robot_description`: the URDF of the leg it serves, published once and latched."""

from __future__ import annotations

from rclpy.node import Node
from rclpy.publisher import Publisher
from std_msgs.msg import String

from g2p.description import LegDescription
from g2p.description.urdf import leg_urdf
from g2p_ros.contract import DESCRIPTION_QOS, ROBOT_DESCRIPTION


def publish_robot_description(node: Node, description: LegDescription | str) -> Publisher:
    """Publish the leg's URDF once on `robot_description` (relative: /leg/robot_description), latched.

    Args:
        node: the rig node.
        description: the leg, written as g2p.description.urdf.leg_urdf does, or a URDF text as it is
            (checked by the caller, e.g. with g2p.description.urdf.parse_leg_urdf).

    Returns:
        The publisher: keep it, destroying it ends the latching.
    """
    text = description if isinstance(description, str) else leg_urdf(description)
    publisher = node.create_publisher(String, ROBOT_DESCRIPTION, DESCRIPTION_QOS)
    publisher.publish(String(data=text))
    return publisher
