"""
The static TF a node reads: the frames a user adds (a table, a camera mount) for its targets.

:func:`make_static_listener` subscribes ``/tf_static`` (tf2_msgs/TFMessage, latched: a node that
starts later still receives every transform published before) and keeps each transform in a
:class:`cbha_inverse.robot.frames.FrameTree`. Only the static tree: the node's own ``/tf``
(the backbone at the tick rate) would cost the control thread a callback per message, and a
target's frame is fixed to the cell. A transform that is not finite is refused (one log line)
and changes nothing.
"""

import importlib

from cbha_inverse.robot.frames import FrameTree
from cbha_inverse.ros.common.qos import TF_STATIC_QOS


class StaticTfListener:
    """
    Keep every transform of ``/tf_static`` in a :class:`FrameTree`.

    Parameters
    ----------
    node : rclpy.node.Node
        The subscribing node.
    message_type : type
        ``tf2_msgs.msg.TFMessage``.

    Attributes
    ----------
    frames : cbha_inverse.robot.frames.FrameTree
        The transforms received.

    """

    def __init__(self, node, message_type):
        """Subscribe ``/tf_static`` (latched)."""
        self.node = node
        self.frames = FrameTree()
        self.received = 0
        self.subscription = node.create_subscription(message_type, '/tf_static', self._on_tf,
                                                     TF_STATIC_QOS)

    def _on_tf(self, message):
        for item in message.transforms:
            t, q = item.transform.translation, item.transform.rotation
            try:
                self.frames.set_transform(item.header.frame_id, item.child_frame_id,
                                          (t.x, t.y, t.z), (q.x, q.y, q.z, q.w))
            except ValueError as exc:
                self.node.get_logger().warning(f'/tf_static refused: {exc}')
                continue
            self.received += 1

    def transform_point(self, point, source, target):
        """Return ``point`` of frame ``source`` in ``target`` (``FrameTree.transform_point``)."""
        return self.frames.transform_point(point, source, target)

    def transform(self, source, target):
        """Return ``source``'s rotation and origin in ``target`` (``FrameTree.transform``)."""
        return self.frames.transform(source, target)


def make_static_listener(node):
    """
    Return a :class:`StaticTfListener` of the node, or None without tf2_msgs.

    Parameters
    ----------
    node : rclpy.node.Node
        The subscribing node.

    Returns
    -------
    StaticTfListener or None

    """
    try:
        return StaticTfListener(node, importlib.import_module('tf2_msgs.msg').TFMessage)
    except (ImportError, AttributeError, RuntimeError):
        # the broadcaster of the same node says in one line why tf2_msgs is not usable
        return None
