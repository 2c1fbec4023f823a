"""
QoS profiles of the package's topics (``docs/nodes.md``), chosen per topic on purpose.

Commands and targets are RELIABLE (a dropped set-point is a missed step); measured streams use the
sensor-data profile (BEST_EFFORT, depth 5: the newest sample matters, an old one is useless). A
best-effort publisher never reaches a reliable subscriber, so subscribers of measured streams use
the sensor-data profile as well.
"""

from rclpy.qos import (
    DurabilityPolicy, HistoryPolicy, qos_profile_sensor_data, QoSProfile, ReliabilityPolicy)


def reliable(depth=10):
    """
    Return a RELIABLE, VOLATILE, KEEP_LAST profile.

    Parameters
    ----------
    depth : int
        History depth.

    Returns
    -------
    rclpy.qos.QoSProfile
        The profile.

    """
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


TARGET_QOS = reliable(10)
"""``target`` (geometry_msgs/PointStamped): reliable, depth 10."""

COMMAND_QOS = reliable(10)
"""``pressure_command`` (std_msgs/Float64MultiArray): reliable, depth 10 (ros2_control style)."""

COMMAND_WRITER_QOS = reliable(1)
"""The controller's ``pressure_command`` writer: reliable, depth 1, so that after a link outage
the reader receives the newest command only, not a burst of those held meanwhile (a writer of
depth 1 matches readers of any depth)."""

MEASURED_QOS = qos_profile_sensor_data
"""``tip/measured`` (geometry_msgs/PointStamped): sensor data (best effort, depth 5)."""

DIAGNOSTICS_QOS = reliable(10)
"""``/diagnostics`` (diagnostic_msgs/DiagnosticArray): reliable."""

MARKER_QOS = reliable(1)
"""``backbone`` (visualization_msgs/MarkerArray): reliable, newest only."""

DRIVER_SET_POINTS_QOS = reliable(10)
"""``/set_bha_pressures`` (robotino_msgs/SetBHAPressures, to the Robotino driver): reliable (a
reliable writer reaches a reliable or a best-effort reader)."""

DRIVER_READINGS_QOS = qos_profile_sensor_data
"""``/bha_readings`` (robotino_msgs/BHAReadings, from the driver): sensor data, so that a driver
that publishes reliable or best effort is received."""

TF_QOS = reliable(100)
"""``/tf`` (tf2_msgs/TFMessage): reliable, volatile, depth 100, as tf2's transform broadcaster."""

TF_STATIC_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                           reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""``/tf_static`` (tf2_msgs/TFMessage): latched (reliable, transient local, depth 1), as tf2's
static broadcaster: a listener that starts later still receives the last message."""

OBSTACLES_QOS = reliable(1)
"""``obstacles`` (visualization_msgs/MarkerArray, into ``cbha_sim``): reliable, volatile, newest
only (a volatile reader matches a latched or a volatile writer)."""

OBSTACLE_MARKERS_QOS = TF_STATIC_QOS
"""``obstacle_markers`` (visualization_msgs/MarkerArray, from ``cbha_sim``): latched (reliable,
transient local, depth 1): RViz started later still draws the obstacles."""
