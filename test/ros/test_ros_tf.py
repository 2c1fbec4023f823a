"""
TF over real DDS, received by plain rclpy subscribers (``cbha_inverse.ros.common.tf``).

``/tf_static``: ``stereo_tracker`` (its console module, started as a user starts it, with the
tf2_msgs that ``make install`` put into the venv) latches the two optical frames of the default
rig; a subscriber that joins afterwards receives them, and they match the rig files, computed
here from the files' numbers with scipy. ``/tf``: ``inverse_solver`` publishes every model
frame and the tip every ``tf_every_n_ticks`` ticks: exactly ``ticks // N`` messages, the frames
equal to its backbone markers and its model state, the tip on the target it converged to, none
with ``0``.
"""

import os
from pathlib import Path
import signal
import subprocess
import sys

from builtin_interfaces.msg import Time
from cbha_inverse.interfaces.colcon_build import interface_environment
from cbha_inverse.paths import config_path
from cbha_inverse.ros.common.conversions import transform_stamped
from cbha_inverse.ros.common.qos import MARKER_QOS, TARGET_QOS, TF_QOS, TF_STATIC_QOS
from cbha_inverse.ros.common.tf import backbone_poses, TfTemplate
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_helpers import (
    child_env, hiding_env, make_node, REPO_ROOT, spin_for, spin_until, target_point)
from scipy.spatial.transform import Rotation
from visualization_msgs.msg import MarkerArray
import yaml

NAMESPACE = '/cbha'
EVERY = 5
TARGET = (0.2308, 0.01, -0.01)
"""A reachable target near the workspace centre of the CBHA scene [m]."""


def _transforms(message):
    """Return ``{child: (parent, (3,) translation, (4,) quaternion)}`` of a TFMessage."""
    out = {}
    for item in message.transforms:
        t, q = item.transform.translation, item.transform.rotation
        out[item.child_frame_id] = (item.header.frame_id, np.array([t.x, t.y, t.z]),
                                    np.array([q.x, q.y, q.z, q.w]))
    return out


def _rig_file_frames():
    """Return the optical frames of the default rig files: ``{child: (translation, rotation)}``."""
    folder = config_path('cameras')
    rig = yaml.safe_load((folder / 'rig.yaml').read_text())
    left, right = (yaml.safe_load((folder / rig[key]).read_text())
                   for key in ('left_camera_info', 'right_camera_info'))
    pose = np.array(rig['base_from_left'], dtype=float)
    base_left = Rotation.from_quat(pose[3:]).as_matrix()
    projection = np.reshape(right['projection_matrix']['data'], (3, 4))
    baseline = -projection[0, 3] / projection[0, 0]
    rectified = [np.reshape(c['rectification_matrix']['data'], (3, 3)) for c in (left, right)]
    # p_left = R_left^T (R_right p_right + [B, 0, 0]) (ROS rectified stereo), then into cbha_base
    base_rect = base_left @ rectified[0].T
    return {'stereo_left_optical': (pose[:3], base_left),
            'stereo_right_optical': (pose[:3] + base_rect @ [baseline, 0.0, 0.0],
                                     base_rect @ rectified[1])}


def _start_tracker(env):
    return subprocess.Popen(
        [sys.executable, '-m', 'cbha_inverse.ros.nodes.stereo_tracker', '--ros-args',
         '--params-file', str(REPO_ROOT / 'config' / 'stereo_tracker.yaml'),
         '-r', f'__ns:={NAMESPACE}'], cwd=REPO_ROOT, env=env, stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, text=True)


def test_stereo_tracker_latches_the_rig_frames_on_tf_static(rclpy_context, tf2_msgs, tmp_path):
    from tf2_msgs.msg import TFMessage
    with_tf = _start_tracker(interface_environment(tf2_msgs, child_env()))
    # without tf2_msgs (hidden: make install puts it into the venv) the node runs, says so once
    # and publishes no TF
    without_tf = _start_tracker(hiding_env(tmp_path, 'tf2_msgs'))
    listener = Node('tf_static_listener', context=rclpy_context)
    executor = SingleThreadedExecutor(context=rclpy_context)
    executor.add_node(listener)
    received = []
    try:
        assert spin_until(executor, lambda: listener.count_publishers('/tf_static') >= 1, 30.0)
        # joins after the publication: only latching (transient local) delivers it
        listener.create_subscription(TFMessage, '/tf_static', received.append, TF_STATIC_QOS)
        assert spin_until(executor, lambda: received, 10.0), 'no /tf_static received'
        # both trackers up (their camera subscriptions come at the end of their start): a
        # SIGINT earlier would stop the one without TF while it loads, before it says so
        assert spin_until(executor, lambda: listener.count_subscribers(
            f'{NAMESPACE}/stereo/right/camera_info') >= 2, 60.0)
        spin_for(executor, 0.5)
    finally:
        executor.shutdown()
        listener.destroy_node()
        outputs = []
        for process in (with_tf, without_tf):
            if process is not None:
                process.send_signal(signal.SIGINT)
                outputs.append((process.communicate(timeout=20)[0], process.returncode))
    assert outputs[0][1] == 0, outputs[0][0]
    frames = _transforms(received[-1])
    expected = _rig_file_frames()
    assert sorted(frames) == sorted(expected)
    for child, (translation, rotation) in expected.items():
        parent, got_translation, quaternion = frames[child]
        assert parent == 'cbha_base'
        np.testing.assert_allclose(got_translation, translation, atol=1e-12)
        np.testing.assert_allclose(Rotation.from_quat(quaternion).as_matrix(), rotation,
                                   atol=1e-12)
    # the default rig: parallel cameras, the right one 0.12 m along +y of cbha_base
    np.testing.assert_allclose(frames['stereo_right_optical'][1], [0.8308, 0.06, -0.0292],
                               atol=1e-12)
    np.testing.assert_allclose(frames['stereo_right_optical'][2], [-0.5, -0.5, 0.5, 0.5],
                               atol=1e-12)
    output, code = outputs[1]
    assert code == 0 and 'no TF: tf2_msgs is not usable' in output, output
    assert 'Traceback' not in output, output


def test_backbone_poses_name_every_frame_and_the_tip():
    rotations = Rotation.from_rotvec([[0.0, 0.0, 0.0], [0.0, 0.3, 0.0], [0.1, 0.5, 0.0]])
    positions = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.2, 0.0, -0.02]])
    names, poses = backbone_poses(positions, rotations.as_matrix(), 2, [0.21, 0.0, -0.02])
    assert names == ['cbha_frame_0', 'cbha_frame_1', 'cbha_frame_2', 'cbha_tip']
    np.testing.assert_allclose(poses[:3, :3], positions)
    np.testing.assert_allclose(poses[3, :3], [0.21, 0.0, -0.02])
    for pose, rotation in zip(poses, [*rotations, rotations[2]]):
        np.testing.assert_allclose(Rotation.from_quat(pose[3:]).as_matrix(),
                                   rotation.as_matrix(), atol=1e-14)


def test_tf_template_serialises_what_the_message_would(tf2_msgs):
    from rclpy.serialization import deserialize_message, serialize_message
    from tf2_msgs.msg import TFMessage
    rng = np.random.default_rng(5)
    children = ['cbha_frame_0', 'a', 'stereo_right_optical', 'cbha_tip']
    template = TfTemplate(TFMessage, 'cbha_base', children)
    for _ in range(3):
        poses = np.hstack([rng.normal(0.0, 0.3, (4, 3)), Rotation.random(4, rng).as_quat()])
        stamp_ns = int(rng.integers(0, 2 ** 31)) * 1_000_000_000 + int(rng.integers(0, 10 ** 9))
        data = template.fill(poses, stamp_ns)
        stamp = Time(sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)
        expected = TFMessage(transforms=[transform_stamped('cbha_base', child, pose, stamp)
                                         for child, pose in zip(children, poses)])
        # the same bytes but the CDR padding (whatever the serialiser leaves there)
        assert len(data) == len(serialize_message(expected))
        assert deserialize_message(data, TFMessage) == expected


def test_inverse_solver_publishes_the_model_frames_on_tf_decimated(rclpy_context, tf2_msgs):
    from tf2_msgs.msg import TFMessage
    solver = make_node(InverseSolverNode, rclpy_context, tf_every_n_ticks=EVERY)
    listener = Node('tf_listener', context=rclpy_context, namespace=NAMESPACE)
    tf_messages, markers = [], []
    listener.create_subscription(TFMessage, '/tf', tf_messages.append, TF_QOS)
    listener.create_subscription(MarkerArray, 'backbone', markers.append, MARKER_QOS)
    target = listener.create_publisher(PointStamped, 'target', TARGET_QOS)
    executor = SingleThreadedExecutor(context=rclpy_context)
    for node in (solver, listener):
        executor.add_node(node)
    try:
        assert spin_until(executor, lambda: target.get_subscription_count() >= 1
                          and listener.count_publishers('/tf') >= 1, 10.0)
        target.publish(target_point(TARGET))
        # stop on a tick that published (one callback per spin: the predicate sees each tick)
        assert spin_until(executor, lambda: solver.ticks >= 100 and markers
                          and solver.ticks % EVERY == 0, 10.0)
        # ticks stop with the solver's spinning; what is in flight still arrives (waited for: a
        # fixed 0.3 s was too short for a listener starved by a loaded machine), and nothing more
        executor.remove_node(solver)
        ticks = solver.ticks
        spin_until(executor, lambda: len(tf_messages) >= ticks // EVERY, 10.0)
        spin_for(executor, 0.3)
        count = len(tf_messages)
        state = solver.solver.state
        assert count == ticks // EVERY, (count, ticks)
        frames = _transforms(tf_messages[-1])
        n_frames = len(state.positions)
        assert list(frames) == [f'cbha_frame_{i}' for i in range(n_frames)] + ['cbha_tip']
        assert {parent for parent, _, _ in frames.values()} == {'cbha_base'}
        # the frames of the last /tf: the model state of the last tick, and the backbone
        # markers of the same node (published on their own timer: a few converging ticks older)
        origins = np.array([frames[f'cbha_frame_{i}'][1] for i in range(n_frames)])
        np.testing.assert_allclose(origins, state.positions, atol=1e-12)
        line = markers[-1].markers[0]
        np.testing.assert_allclose(origins, [[p.x, p.y, p.z] for p in line.points], atol=1e-4)
        for i in range(n_frames):
            np.testing.assert_allclose(
                Rotation.from_quat(frames[f'cbha_frame_{i}'][2]).as_matrix(),
                state.rotations[i], atol=1e-12)
        # the tip (the CBHA's effector: the last vertebra's centre) reached the target
        tip = frames['cbha_tip']
        np.testing.assert_allclose(tip[1], origins[-1], atol=1e-12)
        np.testing.assert_allclose(tip[2], frames[f'cbha_frame_{n_frames - 1}'][2], atol=1e-12)
        assert np.linalg.norm(tip[1] - TARGET) < 1e-3, tip[1]
        # 0 = off, live: the solver keeps ticking, /tf stays silent
        result = solver.set_parameters([Parameter('tf_every_n_ticks', value=0)])
        assert result[0].successful, result[0].reason
        executor.add_node(solver)
        assert spin_until(executor, lambda: solver.ticks >= ticks + 20, 10.0)
        spin_for(executor, 0.2)
        assert len(tf_messages) == count
    finally:
        executor.shutdown()
        for node in (solver, listener):
            node.destroy_node()


def test_rviz_view_shows_every_tf_frame_in_the_solvers_frame():
    from cbha_inverse.ros.nodes.inverse_solver import InverseSolverParams
    view = yaml.safe_load((REPO_ROOT / 'rviz' / 'cbha.rviz').read_text())
    manager = view['Visualization Manager']
    [tf] = [d for d in manager['Displays'] if d['Class'] == 'rviz_default_plugins/TF']
    assert tf['Enabled'] and tf['Frames']['All Enabled'] and tf['Show Axes']
    assert manager['Global Options']['Fixed Frame'] == InverseSolverParams().frame_id


def test_the_built_tfmessage_has_the_type_hash_of_ros_jazzy(tf2_msgs):
    """Match the type hash of ROS 2 Jazzy (its golden value): RViz and tf2 match types by it."""
    import json
    # installed (the venv's share/ beside the wheels', or a sourced ROS 2's), else the build's
    prefixes = [Path(p) for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    prefixes = [tf2_msgs] if tf2_msgs is not None else prefixes + [Path(sys.prefix)]
    [share, *_] = [p / 'share' / 'tf2_msgs' for p in prefixes
                   if (p / 'share' / 'tf2_msgs' / 'msg' / 'TFMessage.json').is_file()]
    description = json.loads((share / 'msg' / 'TFMessage.json').read_text())
    [entry] = [h for h in description['type_hashes'] if h['type_name'] == 'tf2_msgs/msg/TFMessage']
    assert entry['hash_string'] == (
        'RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087')
