"""
The ROS 2 layer (rclpy).

``nodes/`` (one node per module), ``common/`` (what the nodes share), ``bag/`` (the rclpy side of
``cbha_bag``), ``launch/`` (the compositions and ``cbha_launch``) and ``console/``
(``cbha_status``, a console view of ``/diagnostics``). Below this layer nothing
imports rclpy; above it only :mod:`cbha_inverse.experiments` and the bag benchmark
:mod:`cbha_inverse.report.bench_bag` do (see ``docs/design.md``).
"""
