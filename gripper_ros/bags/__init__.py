"""rosbag2 (MCAP) recording, reading, analysis, replay and re-simulation of grasps."""
