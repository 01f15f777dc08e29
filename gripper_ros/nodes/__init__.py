"""The rclpy nodes and what they share: names, QoS, executors, the in-process graph."""
