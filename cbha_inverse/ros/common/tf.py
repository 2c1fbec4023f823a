"""
TF: the frames the nodes broadcast on ``/tf`` and ``/tf_static`` (tf2_msgs/TFMessage).

Frame names (``docs/nodes.md``), every one a child of the node's ``frame_id`` (``cbha_base``):
``cbha_frame_<i>`` is frame ``i`` of the model backbone (0 = the base, ``n`` = the last
vertebra), ``cbha_tip`` the effector (its point on its frame, with that frame's axes), both on
``/tf`` from ``inverse_solver``; ``stereo_left_optical`` and ``stereo_right_optical`` are the raw
optical frames of the stereo rig (x right, y down, z forward), latched on ``/tf_static`` from
``stereo_tracker``.

``tf2_msgs`` is not on PyPI: a ROS 2 install provides it, elsewhere ``cbha_build_tf2_msgs``
builds the shipped copy (:mod:`cbha_inverse.interfaces.tf2_msgs_build`). It is imported when a
node makes its broadcaster; when it cannot be, the node says so in one line and publishes no TF.
"""

import importlib

from cbha_inverse.core.so3 import pose_vector
from cbha_inverse.ros.common.conversions import transform_stamped
from cbha_inverse.ros.common.qos import TF_QOS, TF_STATIC_QOS
import numpy as np

TIP_FRAME = 'cbha_tip'
"""The child frame of the effector (the tip)."""

NO_TF2_MSGS = ('no TF: tf2_msgs is not usable ({error}); source a ROS 2 install, or build it '
               'with `cbha_build_tf2_msgs --workspace WS` and source WS/install/setup.sh')


def backbone_frame(index):
    """Return the child frame name of frame ``index`` of the model backbone (0 = base)."""
    return f'cbha_frame_{index}'


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
        self.sent = 0

    def send(self, parent, children, poses, stamp=None):
        """
        Publish one TFMessage of the children's poses in the parent.

        Parameters
        ----------
        parent : str
            Parent frame of every transform.
        children : sequence of str
            Child frames.
        poses : (len(children), 7) array_like  [m, -]
            ``[x, y, z, qx, qy, qz, qw]`` of each child in the parent.
        stamp : builtin_interfaces.msg.Time, optional
            Stamp of every transform (default: the node clock's now).

        """
        stamp = self.node.get_clock().now().to_msg() if stamp is None else stamp
        self.publisher.publish(self.message_type(transforms=[
            transform_stamped(parent, child, pose, stamp)
            for child, pose in zip(children, poses)]))
        self.sent += 1


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
