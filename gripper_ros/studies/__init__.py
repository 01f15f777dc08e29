"""Studies over the core: step and grip runs, their metrics (no rclpy)."""
