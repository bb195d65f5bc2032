"""The ROS 2 library shared by the G2P nodes (g2p_sim, g2p_driver, g2p_learner, g2p_recorder).

The rig contract's names and QoS, its server and client, message conversion, configuration from ROS
parameters, spinning and signal handling. The algorithm and the plants live in the ROS-free core `g2p`.
"""
