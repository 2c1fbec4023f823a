"""
TF: the frames the nodes broadcast on ``/tf`` and ``/tf_static`` (tf2_msgs/TFMessage).

Frame names (``docs/nodes.md``), every one a child of the node's ``frame_id`` (``cbha_base``):
``cbha_frame_<i>`` is frame ``i`` of the model backbone (0 = the base, ``n`` = the last
vertebra), ``cbha_tip`` the effector (its point on its frame, with that frame's axes), both on
``/tf`` from ``inverse_solver``; ``stereo_left_optical`` and ``stereo_right_optical`` are the raw
optical frames of the stereo rig (x right, y down, z forward), latched on ``/tf_static`` from
``stereo_tracker``. Each obstacle has a frame, its own frame of ``docs/obstacles.md`` (the shape
about its origin): ``obstacle_<name>`` for the plant's obstacles from ``cbha_sim``,
``model_obstacle_<name>`` for those the inverse keeps clear of from ``inverse_solver``, latched
on ``/tf_static`` (the node's whole set in one message, sent again when its ``obstacles`` topic
replaces them; a listener keeps the frame of a removed obstacle, as it keeps any static frame).

``tf2_msgs`` is not on PyPI: a ROS 2 install provides it, and ``make install`` builds the
shipped copy into the venv (:mod:`cbha_inverse.interfaces.venv_install`), where every node finds
it without sourcing anything. It is imported when a node makes its broadcaster; when it cannot
be (an install without it), the node says so in one line and publishes no TF.
"""

import importlib

from builtin_interfaces.msg import Time
from cbha_inverse.core.so3 import pose_vector
from cbha_inverse.ros.common.conversions import transform_stamped
from cbha_inverse.ros.common.qos import TF_QOS, TF_STATIC_QOS
import numpy as np
from rclpy.serialization import serialize_message

TIP_FRAME = 'cbha_tip'
"""The child frame of the effector (the tip)."""

NO_TF2_MSGS = ('no TF: tf2_msgs is not usable ({error}); install it into the venv with '
               '`make install` (python -m cbha_inverse.interfaces.venv_install), or source a '
               'ROS 2 install')


def backbone_frame(index):
    """Return the child frame name of frame ``index`` of the model backbone (0 = base)."""
    return f'cbha_frame_{index}'


def obstacle_frame(name, prefix='obstacle'):
    """Return the child frame name of an obstacle (``<prefix>_<name>``)."""
    return f'{prefix}_{name}'


def obstacle_poses(obstacles, prefix='obstacle'):
    """
    Return the frame names and poses of obstacles.

    Parameters
    ----------
    obstacles : sequence of cbha_inverse.core.obstacles.Obstacle
        The obstacles, posed in the base frame.
    prefix : str
        ``obstacle`` (the plant's) or ``model_obstacle`` (the inverse's).

    Returns
    -------
    names : list of str
        ``<prefix>_<name>`` of each.
    poses : (len(obstacles), 7) ndarray  [m, -]
        ``[x, y, z, qx, qy, qz, qw]`` of each obstacle's own frame in the base frame.

    """
    poses = pose_vector(np.reshape([o.rotation for o in obstacles], (-1, 3, 3)),
                        np.reshape([o.position for o in obstacles], (-1, 3)))
    return [obstacle_frame(o.name, prefix) for o in obstacles], poses


def camera_frame(side):
    """Return the raw optical frame name of a stereo camera (``left`` or ``right``)."""
    return f'stereo_{side}_optical'


def backbone_poses(positions, rotations, tip_frame, tip_position):
    """
    Return the frame names and poses of the model backbone and its tip.

    Parameters
    ----------
    positions : (n + 1, 3) array_like  [m]
        Frame origins (frame 0 = base).
    rotations : (n + 1, 3, 3) array_like
        Frame rotations.
    tip_frame : int
        The frame that carries the effector.
    tip_position : (3,) array_like  [m]
        The effector point.

    Returns
    -------
    names : list of str
        ``cbha_frame_0 .. cbha_frame_n``, then ``cbha_tip``.
    poses : (n + 2, 7) ndarray  [m, -]
        ``[x, y, z, qx, qy, qz, qw]`` of each (the tip with the axes of its frame).

    """
    positions = np.asarray(positions, dtype=float)
    rotations = np.asarray(rotations, dtype=float)
    poses = pose_vector(np.concatenate([rotations, rotations[tip_frame][None]]),
                        np.concatenate([positions, np.reshape(tip_position, (1, 3))]))
    return [backbone_frame(i) for i in range(len(positions))] + [TIP_FRAME], poses


class TfTemplate:
    """
    One TFMessage of fixed frames, serialised once: :meth:`fill` writes only the stamp and poses.

    Building and converting the Python messages of ~20 transforms costs ~50 times what writing
    their numbers into the serialised bytes does. With the frame names fixed, every number has a
    fixed offset in the serialised (CDR) message; the offsets are found by serialising the
    message once with distinct sentinel values (``rclpy.serialization``) and locating their
    bytes, so no CDR layout is written here.

    Parameters
    ----------
    message_type : type
        ``tf2_msgs.msg.TFMessage``.
    parent : str
        Parent frame of every transform.
    children : sequence of str
        Child frames.

    Raises
    ------
    RuntimeError
        If a sentinel is not found exactly once (the serialised layout is not what it assumes).

    """

    def __init__(self, message_type, parent, children):
        self.key = (parent, tuple(children))
        n = len(self.key[1])
        values = -(1.0 + np.arange(7 * n)) * 1.2345678901234567e200
        secs = 0x7A5E0000 + np.arange(n, dtype=np.int32)
        nanosecs = 0x3B9A0000 + np.arange(n, dtype=np.uint32)
        stamps = [Time(sec=int(sec), nanosec=int(nanosec)) for sec, nanosec in zip(secs, nanosecs)]
        data = serialize_message(message_type(transforms=[
            transform_stamped(parent, child, pose, stamp)
            for child, pose, stamp in zip(self.key[1], values.reshape(n, 7), stamps)]))
        self.template = np.frombuffer(data, dtype=np.uint8).copy()
        self.pose_bytes = _byte_offsets(data, values)
        self.sec_bytes = _byte_offsets(data, secs)
        self.nanosec_bytes = _byte_offsets(data, nanosecs)

    def fill(self, poses, stamp_ns):
        """
        Return the serialised message with these poses and this stamp.

        Parameters
        ----------
        poses : (len(children), 7) array_like  [m, -]
            ``[x, y, z, qx, qy, qz, qw]`` of each child in the parent.
        stamp_ns : int  [ns]
            Stamp of every transform.

        Returns
        -------
        bytes
            A serialised TFMessage (``Publisher.publish`` takes it as it is).

        """
        n = len(self.sec_bytes)
        sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
        out = self.template.copy()
        out[self.pose_bytes] = np.ascontiguousarray(poses, dtype=float).reshape(
            7 * n).view(np.uint8).reshape(7 * n, 8)
        out[self.sec_bytes] = np.full(n, sec, dtype=np.int32).view(np.uint8).reshape(n, 4)
        out[self.nanosec_bytes] = np.full(n, nanosec, dtype=np.uint32).view(np.uint8).reshape(
            n, 4)
        return out.tobytes()


def _byte_offsets(data, values):
    """Return the (len(values), itemsize) byte indices of each value's only copy in data."""
    size = values.dtype.itemsize
    starts = []
    for value in values:
        pattern = value.tobytes()
        if data.count(pattern) != 1:
            raise RuntimeError(f'sentinel {value!r} occurs {data.count(pattern)} times')
        starts.append(data.index(pattern))
    return np.asarray(starts, dtype=np.int64)[:, None] + np.arange(size)


class TfBroadcaster:
    """
    A ``/tf`` (or latched ``/tf_static``) publisher of TFMessage.

    Parameters
    ----------
    node : rclpy.node.Node
        The publishing node.
    message_type : type
        ``tf2_msgs.msg.TFMessage``.
    static : bool
        ``/tf_static`` (latched, :data:`~cbha_inverse.ros.common.qos.TF_STATIC_QOS`; send every
        static frame of the node in one message) instead of ``/tf``.

    """

    def __init__(self, node, message_type, static=False):
        self.message_type = message_type
        self.node = node
        self.publisher = node.create_publisher(
            message_type, '/tf_static' if static else '/tf', TF_STATIC_QOS if static else TF_QOS)
        self.template = None
        self.sent = 0
        self.skipped = 0

    def send(self, parent, children, poses, stamp_ns=None):
        """
        Publish one TFMessage of the children's poses in the parent (none if one is not finite).

        Parameters
        ----------
        parent : str
            Parent frame of every transform.
        children : sequence of str
            Child frames.
        poses : (len(children), 7) array_like  [m, -]
            ``[x, y, z, qx, qy, qz, qw]`` of each child in the parent.
        stamp_ns : int, optional  [ns]
            Stamp of every transform (default: the node clock's now).

        Returns
        -------
        bool
            Whether it was published (not finite: counted in :attr:`skipped`).

        """
        poses = np.asarray(poses, dtype=float)
        if not np.all(np.isfinite(poses)):
            self.skipped += 1
            return False
        if self.template is None or self.template.key != (parent, tuple(children)):
            self.template = TfTemplate(self.message_type, parent, children)
        stamp_ns = self.node.get_clock().now().nanoseconds if stamp_ns is None else stamp_ns
        self.publisher.publish(self.template.fill(poses, stamp_ns))
        self.sent += 1
        return True


def make_broadcaster(node, static=False):
    """
    Return a :class:`TfBroadcaster` of the node, or None (said in one INFO line) without tf2_msgs.

    Parameters
    ----------
    node : rclpy.node.Node
        The publishing node.
    static : bool
        ``/tf_static`` instead of ``/tf``.

    Returns
    -------
    TfBroadcaster or None

    """
    try:
        return TfBroadcaster(node, importlib.import_module('tf2_msgs.msg').TFMessage, static)
    except (ImportError, AttributeError, RuntimeError) as exc:
        # RuntimeError: imported, but its type support libraries are not on LD_LIBRARY_PATH
        node.get_logger().info(NO_TF2_MSGS.format(error=str(exc).splitlines()[0]))
        return None
