"""System identification of the gripper plant from recorded runs (no rclpy)."""
