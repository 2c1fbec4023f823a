"""The only rclpy code: thin nodes, conversions, QoS and parameters."""
