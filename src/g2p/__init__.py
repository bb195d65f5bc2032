"""G2P (General to Particular): few-shot learning of locomotion on a tendon-driven leg.

The ROS-free core, in layers; a package imports only the packages below it, as its docstring says
(tests/packaging/test_core_imports.py holds every package to that):

    top-level modules   plant (the plant interface, samples, recordings), safety (the activation range),
                        validation (config checks), files (atomic writes): every layer uses them
    description         the leg's geometry, URDF and packaged models
    inverse_map         the MLP from kinematics to activations
    hardware            the physical rig's chips and buses (what the Pi installs)
    rig                 the tick loop, the safety envelope, closed loop, the `Rig` a learner drives
    sim                 the MuJoCo leg
    hardware_fake       the rig's chips faked on the MuJoCo leg (`--rig hardware_fake`)
    learning            babbling, limit cycles, the reward search, the learner, experiments, checkpoints
    rl                  Gymnasium environments, the RL baselines, sweeps
    bags                bag I/O, training data, reports
    identification      calibration of the simulated rig from a recorded run
    viewer              the live view in Foxglove

Nothing here imports rclpy.
"""

__version__ = "0.1.0"
