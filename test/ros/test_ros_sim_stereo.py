"""``cbha_sim`` with rendered cameras feeding ``stereo_tracker``; no OpenCV without cameras."""

import subprocess
import sys

from cbha_inverse.ros.common.qos import MEASURED_QOS, reliable
from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode
from cbha_inverse.ros.nodes.stereo_tracker import StereoTrackerNode
from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_helpers import child_env, REPO_ROOT, spin_for, spin_until
from sensor_msgs.msg import CameraInfo, Image

NO_CAMERA_RUN = """
import cbha_inverse.experiments.demo
from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
import cbha_inverse.ros.nodes.trajectory
import rclpy
from rclpy.executors import SingleThreadedExecutor
import sys
rclpy.init()
nodes = [CbhaSimNode(namespace='/cbha'), InverseSolverNode(namespace='/cbha')]
executor = SingleThreadedExecutor()
for node in nodes:
    executor.add_node(node)
for _ in range(20):
    executor.spin_once(timeout_sec=0.02)
print('ticks', nodes[0].tick_times.count, 'cv2' in sys.modules)
"""


def test_run_without_cameras_never_imports_cv2():
    """The plant (point output), the solver, trajectory and demo modules never import cv2."""
    result = subprocess.run([sys.executable, '-c', NO_CAMERA_RUN], cwd=REPO_ROOT,
                            env=child_env(), capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
    words = result.stdout.split()
    assert words[0] == 'ticks' and int(words[1]) > 0, result.stdout
    assert words[2] == 'False', 'cv2 was imported by a run without cameras'


def test_sim_stereo_output_is_tracked_to_the_true_tip(rclpy_context):
    """tip_output: stereo publishes images, no tip/measured; the tracker finds the true tip."""
    sim = CbhaSimNode(context=rclpy_context, namespace='/cbha', parameter_overrides=[
        Parameter('tip_output', value='stereo'),
        Parameter('camera_rig', value='cameras/demo_rig.yaml'),
        Parameter('camera_rate_hz', value=20.0)])
    probe = Node('stereo_probe', context=rclpy_context, namespace='/cbha')
    measured, truth, images, right_images, infos = [], [], [], [], []
    probe.create_subscription(PointStamped, 'tip/measured', measured.append, MEASURED_QOS)
    probe.create_subscription(PointStamped, 'tip/true', truth.append, MEASURED_QOS)
    probe.create_subscription(Image, 'stereo/left/image_raw', images.append, reliable(2))
    probe.create_subscription(Image, 'stereo/right/image_raw', right_images.append, reliable(2))
    probe.create_subscription(CameraInfo, 'stereo/right/camera_info', infos.append, 10)
    executor = SingleThreadedExecutor(context=rclpy_context)
    for node in (sim, probe):
        executor.add_node(node)
    tracker = None
    try:
        assert spin_until(executor, lambda: len(images) >= 3 and infos and truth, 20.0)
        spin_for(executor, 0.3)
        assert not measured, 'cbha_sim published tip/measured in stereo mode'
        assert (images[-1].width, images[-1].height, images[-1].encoding) == (640, 512, 'bgr8')
        assert infos[-1].p[3] < 0.0
        stamps = {(m.header.stamp.sec, m.header.stamp.nanosec) for m in images}
        assert any((m.header.stamp.sec, m.header.stamp.nanosec) in stamps for m in right_images)
        tracker = StereoTrackerNode(context=rclpy_context, namespace='/cbha',
                                    parameter_overrides=[
                                        Parameter('left_camera_info_file', value=''),
                                        Parameter('right_camera_info_file', value='')])
        executor.add_node(tracker)
        assert spin_until(executor, lambda: len(measured) >= 5, 20.0), tracker.counts
    finally:
        executor.shutdown()
        for node in (sim, probe, tracker):
            if node is not None:
                node.destroy_node()
    tip = np.array([truth[-1].point.x, truth[-1].point.y, truth[-1].point.z])
    points = np.array([[m.point.x, m.point.y, m.point.z] for m in measured])
    errors = np.linalg.norm(points - tip, axis=1)
    assert errors.max() < 0.5e-3, errors
    assert {m.header.frame_id for m in measured} == {'cbha_base'}
