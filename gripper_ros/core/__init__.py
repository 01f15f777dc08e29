"""The numeric core, no rclpy: physics, control, supervision and runtime, each a subpackage."""
