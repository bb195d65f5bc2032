"""ROS 2 adapters shared by the G2P nodes (g2p_sim, g2p_driver, g2p_learner).

Message conversion, the rig contract's names and QoS, configuration from ROS parameters, and the rig
contract server. The algorithm and the plants live in the ROS-free core library `g2p`.
"""
