"""The leg's description: its geometry, forward kinematics, URDF, and the packaged models.

- `leg`: `LegDescription` (links, joints, foot pad) and its forward kinematics; re-exported here.
- `urdf`: the URDF the rig nodes publish as `robot_description`, written and read back.
- `models/`: the packaged MuJoCo model (leg.xml), its URDF (leg.urdf) and calibrations.

May import: nothing of g2p beyond the top-level modules.
"""

from g2p.description.leg import FloatArray, Joint, LegDescription, Link, foot_path, forward_kinematics

__all__ = ["FloatArray", "Joint", "LegDescription", "Link", "foot_path", "forward_kinematics"]
