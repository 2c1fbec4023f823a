"""Conversions between ROS messages and numpy arrays (no maths here)."""

from array import array

from geometry_msgs.msg import Point, PointStamped, TransformStamped
import numpy as np
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from visualization_msgs.msg import Marker, MarkerArray


def point_array(message):
    """Return the (3,) point [m] of a ``PointStamped`` (NaN/inf pass through for validation)."""
    point = message.point
    return np.array([point.x, point.y, point.z], dtype=float)


def point_values(message):
    """Return the point of a ``PointStamped`` as a list of three floats [m] (unchecked)."""
    point = message.point
    return [point.x, point.y, point.z]


def stamp_ns(stamp):
    """Return a ``builtin_interfaces/Time`` in integer nanoseconds."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def stamp_seconds(stamp):
    """Return a ``builtin_interfaces/Time`` in seconds (float)."""
    return stamp.sec + 1e-9 * stamp.nanosec


def point_stamped(point, stamp, frame_id):
    """
    Build a ``PointStamped``.

    Parameters
    ----------
    point : (3,) array_like  [m]
        Coordinates.
    stamp : builtin_interfaces.msg.Time
        Header stamp.
    frame_id : str
        Header frame.

    Returns
    -------
    geometry_msgs.msg.PointStamped
        The message.

    """
    message = PointStamped()
    message.header.stamp = stamp
    message.header.frame_id = frame_id
    message.point.x, message.point.y, message.point.z = np.asarray(point, dtype=float).tolist()
    return message


def transform_stamped(parent, child, pose, stamp):
    """
    Build a ``TransformStamped`` (one entry of ``/tf`` or ``/tf_static``).

    Parameters
    ----------
    parent, child : str
        ``header.frame_id`` and ``child_frame_id``.
    pose : (7,) array_like  [m, -]
        The child frame in the parent, ``[x, y, z, qx, qy, qz, qw]``.
    stamp : builtin_interfaces.msg.Time
        Header stamp.

    Returns
    -------
    geometry_msgs.msg.TransformStamped
        The message.

    """
    message = TransformStamped()
    message.header.stamp = stamp
    message.header.frame_id = parent
    message.child_frame_id = child
    x, y, z, qx, qy, qz, qw = np.asarray(pose, dtype=float).reshape(7).tolist()
    translation, rotation = message.transform.translation, message.transform.rotation
    translation.x, translation.y, translation.z = x, y, z
    rotation.x, rotation.y, rotation.z, rotation.w = qx, qy, qz, qw
    return message


def joint_state(names, positions, stamp, frame_id):
    """
    Build a ``JointState`` of named raw readings (the ``string_pots`` topic).

    Parameters
    ----------
    names : sequence of str
        One name per reading.
    positions : (c,) array_like
        The readings.
    stamp : builtin_interfaces.msg.Time
        Header stamp.
    frame_id : str
        Header frame.

    Returns
    -------
    sensor_msgs.msg.JointState

    """
    message = JointState()
    message.header.stamp = stamp
    message.header.frame_id = frame_id
    message.name = list(names)
    message.position = [float(v) for v in positions]
    return message


def joint_positions(message, names):
    """
    Return the positions of a ``JointState`` in the order of ``names``.

    Parameters
    ----------
    message : sensor_msgs.msg.JointState
        The message.
    names : sequence of str
        The wanted names.

    Returns
    -------
    (c,) ndarray or None
        None when a name is missing or the message's names and positions differ in number
        (NaN/inf pass through for validation).

    """
    if len(message.name) != len(message.position):
        return None
    index = {name: k for k, name in enumerate(message.name)}
    if any(name not in index for name in names):
        return None
    return np.array([message.position[index[name]] for name in names], dtype=float)


def command_message(values, valve_names):
    """
    Build a pressure command (ros2_control forward-command style).

    Parameters
    ----------
    values : (m,) array_like  [Pa]
        Gauge pressures in valve order.
    valve_names : sequence of str
        Valve names; joined with commas as the label of the single layout dimension.

    Returns
    -------
    std_msgs.msg.Float64MultiArray
        ``data`` = the pressures (:func:`command_data`).

    """
    message = Float64MultiArray()
    size = len(valve_names)
    message.layout.dim = [MultiArrayDimension(label=','.join(valve_names), size=size,
                                              stride=size)]
    message.data = command_data(values)
    return message


def command_data(values):
    """
    Return pressures as the ``data`` of a ``Float64MultiArray``.

    Parameters
    ----------
    values : (m,) array_like  [Pa]
        Gauge pressures in valve order.

    Returns
    -------
    array.array
        An ``array('d')`` filled from the values' bytes: no Python float per value, no
        per-element check in the message's setter (a node that publishes at the tick rate
        keeps one message from :func:`command_message` and replaces only its ``data``).

    """
    data = array('d')
    data.frombytes(np.asarray(values, dtype=np.float64).reshape(-1).tobytes())
    return data


class SerializedCommand:
    """
    A pressure command as its serialized ``Float64MultiArray``, the pressures replaced in place.

    ``Publisher.publish`` takes the CDR bytes of a message as they are: the command's layout
    (:func:`command_message`) is serialized once, by rclpy, and each command only overwrites
    the m doubles at the end of those bytes. This skips the conversion of a Python message
    into its C struct on every publication (tens of microseconds with the caches cold, the
    usual case at a 100 Hz tick: ``docs/nodes.md``, "Latency"). The layout is checked at
    construction: a probe command must deserialize to itself.

    Parameters
    ----------
    valve_names : sequence of str
        The valves, in command order (the layout's label).

    Raises
    ------
    RuntimeError
        If the serialized message does not end with its m doubles in this machine's byte order
        (then publish :func:`command_message` instead).

    """

    def __init__(self, valve_names):
        """Serialize the layout once and check where the pressures lie."""
        self.size = len(valve_names)
        probe = np.arange(1.0, self.size + 1.0)
        template = command_message(probe, valve_names)
        self._buffer = bytearray(serialize_message(template))
        self._offset = len(self._buffer) - 8 * self.size
        decoded = deserialize_message(self.serialize(probe), Float64MultiArray)
        if decoded.layout != template.layout or list(decoded.data) != probe.tolist():
            raise RuntimeError('a Float64MultiArray does not serialize with its data last, '
                               'in native byte order')

    def serialize(self, values):
        """
        Return the serialized command of m pressures.

        Parameters
        ----------
        values : (m,) float64 ndarray  [Pa]
            Gauge pressures in valve order (already through the command gate).

        Returns
        -------
        bytes
            For ``Publisher.publish`` of a ``Float64MultiArray`` publisher.

        Raises
        ------
        ValueError
            If ``values`` is not m float64 values.

        """
        if (type(values) is not np.ndarray or values.dtype != np.float64
                or values.shape != (self.size,)):
            raise ValueError(f'a command of {self.size} float64 values, not {values!r}')
        self._buffer[self._offset:] = values.tobytes()
        return bytes(self._buffer)


def command_array(message):
    """Return ``Float64MultiArray.data`` as a float ndarray (any length, unchecked)."""
    return np.asarray(message.data, dtype=float).reshape(-1)


def plain_marker(stamp, frame_id, namespace, marker_id, kind, rgba):
    """
    Return an ADD ``visualization_msgs/Marker`` of one colour (pose and scale left to the caller).

    Parameters
    ----------
    stamp : builtin_interfaces.msg.Time
        Header stamp.
    frame_id : str
        Header frame.
    namespace : str
        Marker namespace.
    marker_id : int
        Marker id within the namespace.
    kind : int
        ``Marker.SPHERE``, ``Marker.ARROW``, ...
    rgba : (4,) sequence of float
        Colour, 0..1.

    Returns
    -------
    visualization_msgs.msg.Marker

    """
    item = Marker()
    item.header.stamp = stamp
    item.header.frame_id = frame_id
    item.ns = namespace
    item.id = marker_id
    item.type = kind
    item.action = Marker.ADD
    item.color.r, item.color.g, item.color.b, item.color.a = (float(v) for v in rgba)
    return item


def backbone_markers(positions, target, stamp, frame_id, namespace='backbone'):
    """
    Build the RViz markers of the model backbone and the current target.

    Parameters
    ----------
    positions : (n + 1, 3) array_like  [m]
        Frame origins of the model (frame 0 = base).
    target : (3,) array_like or None  [m]
        Current target (not drawn if None).
    stamp : builtin_interfaces.msg.Time
        Header stamp.
    frame_id : str
        Header frame.
    namespace : str
        Marker namespace.

    Returns
    -------
    visualization_msgs.msg.MarkerArray
        A LINE_STRIP through the frames, a SPHERE_LIST on the frames and a SPHERE at the target.

    """
    def marker(marker_id, kind, scale, rgb):
        item = plain_marker(stamp, frame_id, namespace, marker_id, kind, (*rgb, 1.0))
        item.pose.orientation.w = 1.0
        item.scale.x = item.scale.y = item.scale.z = scale
        return item

    points = [Point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in positions]
    line = marker(0, Marker.LINE_STRIP, 0.004, (0.2, 0.5, 1.0))
    line.points = points
    frames = marker(1, Marker.SPHERE_LIST, 0.008, (0.9, 0.9, 0.9))
    frames.points = points
    markers = [line, frames]
    if target is not None:
        goal = marker(2, Marker.SPHERE, 0.01, (1.0, 0.3, 0.1))
        goal.pose.position = Point(x=float(target[0]), y=float(target[1]), z=float(target[2]))
        markers.append(goal)
    return MarkerArray(markers=markers)
