"""ROS 2 nodes: one node per module (module name = node name = executable name)."""
