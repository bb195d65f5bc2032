"""Raspberry Pi driver for the physical G2P rig, serving the rig contract."""
