"""MuJoCo simulation of the G2P tendon-driven leg on a treadmill, serving the rig contract."""
