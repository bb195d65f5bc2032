"""The physical rig's chips faked byte for byte, backed by the MuJoCo leg (`--rig hardware_fake`).

The driver's real code (g2p.hardware) runs on these buses, with faults injected on cue.

- `chips`: fake AS5048A encoders, LS7366R counter, PCA9685 PWM, INA219 current sensors, GPIO and sysfs PWM.
- `buses`: `FakeBuses`, the fake chips wired to a `g2p.sim.MujocoLeg`.

May import: g2p.hardware, g2p.sim.
"""
