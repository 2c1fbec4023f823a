"""
ROS 2 nodes: one node per module (module name = node name = executable name).

A stop signal while a node executable still loads is a quiet exit: see :mod:`cbha_inverse.ros`.
"""
