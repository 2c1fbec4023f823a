"""The rclpy side of the bag tools: ``cbha_bag`` (record, play, info, eval)."""
