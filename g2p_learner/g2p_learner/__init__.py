"""G2P learner: motor babbling, inverse-map refinement and reward search as ROS 2 actions."""
