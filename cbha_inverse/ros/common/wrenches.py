"""
Run-time external loads over ROS: a ``geometry_msgs/WrenchStamped`` per loaded frame.

A node with ``wrench_frames`` set (``cbha_sim``, ``inverse_solver``) subscribes, for each entry
(``tip`` or a frame index 1..n), ``wrench/tip`` or ``wrench/frame_<i>`` (reliable; a ROS name
token cannot start with a digit).
A message sets the wrench on that frame's origin, replacing the previous one of the topic
(``docs/loads.md``):

- ``header.frame_id`` = the node's base frame (``frame_id``, ``cbha_base``): a dead wrench in
  base-frame axes;
- ``header.frame_id`` = the frame's own name on ``/tf`` (``cbha_frame_<i>``,
  :func:`cbha_inverse.ros.common.tf.backbone_frame`): a follower wrench in its axes (it turns
  with the frame).

Force [N] and torque [N*m] must be finite; any other ``frame_id`` is refused (a frame
transform is not guessed). A refused message is counted and logged (``wrench.<reason>``) and
the load stays what it was; an all-zero wrench removes it.
"""

from cbha_inverse.core.loads import Load
from cbha_inverse.ros.common.params import ParameterError
from cbha_inverse.ros.common.qos import TARGET_QOS
from cbha_inverse.ros.common.tf import backbone_frame
from geometry_msgs.msg import WrenchStamped
import numpy as np


def wrench_frames(entries, n_links):
    """
    Return the loaded frames of a node's ``wrench_frames`` parameter.

    Parameters
    ----------
    entries : tuple of str or None
        ``'tip'`` or a frame index (1..n) each; None or empty: none.
    n_links : int
        Links of the chain (n).

    Returns
    -------
    list of (str, int)
        ``(topic, frame index)`` per entry.

    Raises
    ------
    ParameterError
        On an entry that is neither ``tip`` nor an index in 1..n, or one given twice.

    """
    frames = []
    for entry in entries or ():
        entry = str(entry).strip()
        if entry != 'tip' and not (entry.isdigit() and 1 <= int(entry) <= n_links):
            raise ParameterError(f"wrench_frames: {entry!r} is neither 'tip' nor a frame index "
                                 f'in 1..{n_links}')
        index = n_links if entry == 'tip' else int(entry)
        if index in [frame for _, frame in frames]:
            raise ParameterError(f'wrench_frames: frame {index} given twice')
        frames.append(('wrench/tip' if entry == 'tip' else f'wrench/frame_{index}', index))
    return frames


def wrench_load(topic, frame, message, base_frame):
    """
    Return the load of a ``WrenchStamped`` on ``frame``, or why it is refused.

    Parameters
    ----------
    topic : str
        The topic (the load's name).
    frame : int
        The frame it acts on (1..n).
    message : geometry_msgs.msg.WrenchStamped
        The message.
    base_frame : str
        The node's base frame name.

    Returns
    -------
    load : cbha_inverse.core.loads.Load or None
        The load (None when refused).
    refused : (str, str) or None
        ``(reason, detail)`` when refused: ``'non_finite'`` or ``'frame'``.

    """
    force, torque = message.wrench.force, message.wrench.torque
    values = np.array([force.x, force.y, force.z, torque.x, torque.y, torque.z])
    if not np.all(np.isfinite(values)):
        return None, ('non_finite', f'{topic}: force and torque must be finite, got '
                      f'{values.tolist()}')
    frame_id = message.header.frame_id
    own = backbone_frame(frame)
    if frame_id not in (base_frame, own):
        return None, ('frame', f'{topic}: frame_id {frame_id!r} is neither {base_frame!r} '
                      f"(base axes) nor {own!r} (the frame's own axes)")
    return Load.of_wrench(topic, frame, values[:3], values[3:],
                          'base' if frame_id == base_frame else 'local'), None


class WrenchInputs:
    """
    The ``wrench/tip`` and ``wrench/frame_<i>`` subscriptions of a node and their loads.

    Parameters
    ----------
    node : rclpy.node.Node
        The node (subscribes).
    entries : tuple of str or None
        Its ``wrench_frames`` parameter (:func:`wrench_frames`).
    n_links : int
        Links of the chain (n).
    loads : cbha_inverse.core.loads.Loads
        The loads before any message (the scene's).
    base_frame : str
        The node's base frame name.
    apply : callable
        ``apply(loads)``: called with the new loads after each accepted message.
    reject : callable
        ``reject(reason, detail)``: called for each refused message.

    Raises
    ------
    ParameterError
        As :func:`wrench_frames`.

    """

    def __init__(self, node, entries, n_links, loads, base_frame, apply, reject):
        """Subscribe each loaded frame's topic."""
        self.loads = loads
        self.received = 0
        self._base_frame, self._apply, self._reject = base_frame, apply, reject
        self.topics = wrench_frames(entries, n_links)
        for topic, frame in self.topics:
            node.create_subscription(
                WrenchStamped, topic,
                lambda message, topic=topic, frame=frame: self._on_wrench(topic, frame, message),
                TARGET_QOS)

    def _on_wrench(self, topic, frame, message):
        load, refused = wrench_load(topic, frame, message, self._base_frame)
        if refused is not None:
            self._reject(*refused)
            return
        self.received += 1
        self.loads = (self.loads.without(topic) if not any(load.wrench)
                      else self.loads.updated(load))
        self._apply(self.loads)
