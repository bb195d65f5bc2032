"""The live view of a G2P run in Foxglove (`ros2 run g2p_viewer view`)."""
