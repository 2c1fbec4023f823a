"""
Obstacle frames on ``/tf_static`` over real DDS (``cbha_inverse.ros.common.tf``).

``cbha_sim`` latches a frame ``obstacle_<name>`` per obstacle of its plant, ``inverse_solver`` a
frame ``model_obstacle_<name>`` per obstacle its rows keep clear of, both from the scene's base
frame. A listener that joins after them receives the scene's obstacles (``cbha_post``: the
poses checked against the scene file's numbers); an ``obstacles`` message replaces them: each
node sends the new set (an empty one for none), and a listener that joins afterwards receives
only that set.
"""

from cbha_inverse.paths import config_path
from cbha_inverse.ros.common.qos import OBSTACLES_QOS
from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
import numpy as np
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from ros_helpers import make_node, spin_until, spinning
from scipy.spatial.transform import Rotation
from visualization_msgs.msg import Marker, MarkerArray
import yaml

NAMESPACE = '/cbha'
LISTENER_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                          reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""A tf2 listener's ``/tf_static`` reader: latched, deep enough for one message per writer
(a depth-1 reader keeps one sample of all writers together)."""
CRATE_POSITION = (0.3, 0.1, -0.02)
CRATE_ROTATION = Rotation.from_euler('xyz', [0.2, -0.4, 1.1])


def _transforms(messages):
    """Return ``{child: (parent, (3,) translation, (3, 3) rotation)}`` of TFMessages."""
    out = {}
    for message in messages:
        for item in message.transforms:
            t, q = item.transform.translation, item.transform.rotation
            out[item.child_frame_id] = (item.header.frame_id, np.array([t.x, t.y, t.z]),
                                        Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix())
    return out


def _scene_file_poses():
    """Return ``{name: (position, rotation)}`` of the obstacles of ``cbha_post.yaml``."""
    entries = yaml.safe_load(config_path('scenes/cbha_post.yaml').read_text())['obstacles']
    out = {}
    for entry in entries:
        pose = entry.get('pose', {})
        roll, pitch, yaw = pose.get('rpy', [0.0, 0.0, 0.0])
        # R = Rz(yaw) Ry(pitch) Rx(roll) (docs/obstacles.md): extrinsic x, y, z
        out[entry['name']] = (np.array(pose.get('position', [0.0, 0.0, 0.0])),
                              Rotation.from_euler('xyz', [roll, pitch, yaw]).as_matrix())
    return out


def _crate():
    item = Marker()
    item.header.frame_id = 'cbha_base'
    item.ns, item.id, item.type, item.action = 'lab', 0, Marker.CUBE, Marker.ADD
    item.pose.position.x, item.pose.position.y, item.pose.position.z = CRATE_POSITION
    x, y, z, w = CRATE_ROTATION.as_quat()
    item.pose.orientation.x, item.pose.orientation.y = x, y
    item.pose.orientation.z, item.pose.orientation.w = z, w
    item.scale.x, item.scale.y, item.scale.z = 0.05, 0.04, 0.03
    return item


def test_obstacle_frames_follow_the_obstacle_sets(rclpy_context, tf2_msgs):
    from tf2_msgs.msg import TFMessage
    sim = make_node(CbhaSimNode, rclpy_context, namespace=NAMESPACE, scene='cbha_post')
    solver = make_node(InverseSolverNode, rclpy_context, scene='cbha_post')
    listener = Node('obstacle_tf_listener', context=rclpy_context, namespace=NAMESPACE)
    obstacles = listener.create_publisher(MarkerArray, 'obstacles', OBSTACLES_QOS)
    early, late = [], []
    with spinning(rclpy_context, sim, solver, listener) as executor:
        assert spin_until(executor, lambda: listener.count_publishers('/tf_static') >= 2, 10.0)
        # joins after both sent: only latching delivers the scene's frames
        listener.create_subscription(TFMessage, '/tf_static', early.append, LISTENER_QOS)
        assert spin_until(executor, lambda: len(early) >= 2, 10.0)
        frames = _transforms(early)
        expected = _scene_file_poses()
        assert sorted(frames) == sorted([f'obstacle_{name}' for name in expected]
                                        + [f'model_obstacle_{name}' for name in expected])
        for name, (position, rotation) in expected.items():
            for prefix in ('obstacle', 'model_obstacle'):
                parent, translation, got = frames[f'{prefix}_{name}']
                assert parent == 'cbha_base'
                np.testing.assert_allclose(translation, position, atol=1e-12)
                np.testing.assert_allclose(got, rotation, atol=1e-12)
        # a new set through the obstacles topic: both nodes send it
        assert spin_until(executor, lambda: obstacles.get_subscription_count() >= 2, 10.0)
        obstacles.publish(MarkerArray(markers=[_crate()]))
        assert spin_until(executor, lambda: len(early) >= 4, 10.0)
        assert sim.obstacle_updates == 1 and solver.obstacle_updates == 1
        replaced = _transforms(early[2:])
        assert sorted(replaced) == ['model_obstacle_lab/0', 'obstacle_lab/0']
        for parent, translation, rotation in replaced.values():
            assert parent == 'cbha_base'
            np.testing.assert_allclose(translation, CRATE_POSITION, atol=1e-12)
            np.testing.assert_allclose(rotation, CRATE_ROTATION.as_matrix(), atol=1e-9)
        # a listener that joins now receives the replaced sets only
        listener.create_subscription(TFMessage, '/tf_static', late.append, LISTENER_QOS)
        assert spin_until(executor, lambda: len(late) >= 2, 10.0)
        assert sorted(_transforms(late)) == ['model_obstacle_lab/0', 'obstacle_lab/0']
        # an empty set: each node sends a message without frames
        obstacles.publish(MarkerArray())
        assert spin_until(executor, lambda: len(early) >= 6, 10.0)
        assert [len(message.transforms) for message in early[4:]] == [0, 0]
