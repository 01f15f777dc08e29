"""System identification of the gripper plant: the excitation experiment and the fit (no rclpy)."""
