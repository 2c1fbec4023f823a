"""Offline condensation of volumetric FE segments onto rigid vertebra frames (no ROS)."""
