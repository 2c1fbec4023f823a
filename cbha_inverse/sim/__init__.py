"""The simulated arm, no ROS: the plant (static solve under load) and the valve line."""
