"""The numeric core: plant, sensor, controllers, supervisor logic, headless loop (no rclpy)."""
