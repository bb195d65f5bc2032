"""Recording of the G2P graph to rosbag2 MCAP bags, and their replay."""
