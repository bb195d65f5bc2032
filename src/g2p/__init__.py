"""G2P (General to Particular): few-shot learning of locomotion on a tendon-driven leg.

The ROS-free core: babbling, preprocessing, the inverse map, limit cycles, the reward search, the
plants (MuJoCo simulation and hardware) and bag I/O. Nothing here imports rclpy.
"""

__version__ = "0.1.0"
