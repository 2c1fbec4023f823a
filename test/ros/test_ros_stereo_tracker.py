"""
The installed ``stereo_tracker`` over real DDS, fed rendered images and camera_info by this test.

The node runs as its console script (``stereo_tracker``, as ``ros2 run`` would start it) with the
installed params file; its camera models come from the camera_info topics only (the YAML
fallback is switched off), so the test also checks that path.
"""

from pathlib import Path
import signal
import subprocess
import sys

from builtin_interfaces.msg import Time
from cbha_inverse.paths import config_path
from cbha_inverse.ros.common.images import camera_info_message, image_message
from cbha_inverse.ros.common.qos import DIAGNOSTICS_QOS, MEASURED_QOS, reliable
from cbha_inverse.vision.render import StereoRenderer
from cbha_inverse.vision.rig import load_rig
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
import numpy as np
import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from ros_helpers import child_env, spin_until
from sensor_msgs.msg import CameraInfo, Image
import yaml

NAMESPACE = '/cbha'


class Feeder:
    """Publish images and camera_info, record tip/measured and the tracker's diagnostics."""

    def __init__(self, context):
        self.node = Node('stereo_feeder', context=context, namespace=NAMESPACE)
        self.images = {side: self.node.create_publisher(Image, f'stereo/{side}/image_raw',
                                                        reliable(2)) for side in ('left', 'right')}
        self.infos = {side: self.node.create_publisher(CameraInfo, f'stereo/{side}/camera_info',
                                                       10) for side in ('left', 'right')}
        self.points = []
        self.diagnostics = {}
        self.node.create_subscription(PointStamped, 'tip/measured', self.points.append,
                                      MEASURED_QOS)
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics,
                                      DIAGNOSTICS_QOS)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)

    def _on_diagnostics(self, message):
        for status in message.status:
            if status.name == 'stereo_tracker: tracking':
                self.diagnostics = {v.key: v.value for v in status.values}

    def count(self, key):
        """Return a diagnostics counter (0 when absent)."""
        return int(self.diagnostics.get(key, 0))

    def publish_pair(self, left, right, stamps, encoding='bgr8', edit=None):
        """Publish one pair (optionally edited messages); stamps in seconds."""
        for side, pixels, stamp in (('left', left, stamps[0]), ('right', right, stamps[1])):
            sec = int(stamp)
            message = image_message(pixels, 'bgr8', Time(sec=sec, nanosec=int(
                round((stamp - sec) * 1e9))), f'{side}_optical')
            message.encoding = encoding
            if edit is not None and side == 'left':
                edit(message)
            self.images[side].publish(message)


@pytest.fixture(scope='module')
def rig():
    """Load the default 1280x1024 rig."""
    return load_rig(config_path('cameras', 'rig.yaml'))


def test_installed_tracker_over_dds(rclpy_context, rig, tmp_path):
    """Good pairs give the true tip (RMS <= 0.3 mm); bad inputs publish nothing and are counted."""
    executable = Path(sys.executable).with_name('stereo_tracker')
    assert executable.is_file(), 'stereo_tracker console script not installed (make install)'
    overrides = tmp_path / 'overrides.yaml'
    overrides.write_text(yaml.safe_dump({'/**': {'ros__parameters': {
        'left_camera_info_file': '', 'right_camera_info_file': '',
        'diagnostics_period': 0.2, 'log_throttle': 0.0}}}))
    process = subprocess.Popen(
        [str(executable), '--ros-args', '-r', f'__ns:={NAMESPACE}', '--params-file',
         str(config_path('stereo_tracker.yaml')), '--params-file', str(overrides),
         # the node's own logger at DEBUG: its drop lines are shown, at their level
         '--log-level', f"{NAMESPACE.strip('/').replace('/', '.')}.stereo_tracker:=debug"],
        env=child_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    feeder = Feeder(rclpy_context)
    renderer = StereoRenderer(rig, seed=4)
    rng = np.random.default_rng(9)
    truth = {}
    try:
        assert spin_until(feeder.executor, lambda: feeder.diagnostics and all(
            p.get_subscription_count() for p in feeder.images.values()), 30.0), 'no tracker'
        point = np.array([0.22, 0.02, -0.04])
        left, right = renderer.render(point)
        feeder.publish_pair(left, right, (10.0, 10.0))
        assert spin_until(feeder.executor, lambda: feeder.count('rejected.no_camera_model') == 2,
                          10.0), feeder.diagnostics

        def camera_models_from_topics():
            # drivers publish camera_info with every image: repeat until the tracker uses them
            for side, camera in (('left', rig.left), ('right', rig.right)):
                feeder.infos[side].publish(camera_info_message(camera, Time(sec=1),
                                                               f'{side}_optical'))
            spin_until(feeder.executor, lambda: False, 0.1)
            return feeder.diagnostics.get('camera_models', '').count('topic') == 2

        assert spin_until(feeder.executor, camera_models_from_topics, 10.0), feeder.diagnostics

        def good_pair(stamp):
            p_base = rng.uniform([0.17, -0.09, -0.12], [0.25, 0.09, 0.06])
            truth[stamp] = p_base
            expected = len(feeder.points) + 1
            feeder.publish_pair(*renderer.render(p_base), (stamp, stamp))
            assert spin_until(feeder.executor, lambda: len(feeder.points) >= expected, 15.0), (
                feeder.diagnostics)

        for index in range(8):
            good_pair(20.0 + index)
        # left and right 50 ms apart: never paired (max_pair_dt 2 ms), dropped when stale
        feeder.publish_pair(left, right, (40.0, 40.05))
        # the marker in one image only
        empty, _ = renderer.render(point + [5.0, 0.0, 0.0])
        feeder.publish_pair(left, empty, (41.0, 41.0))
        assert spin_until(feeder.executor, lambda: feeder.count('rejected.no_marker_right') == 1,
                          10.0), feeder.diagnostics
        feeder.publish_pair(left, right, (42.0, 42.0), encoding='bgra8')
        feeder.publish_pair(left, right, (43.0, 43.0), encoding='16UC1')
        assert spin_until(feeder.executor, lambda: feeder.count('rejected.encoding') == 4,
                          10.0), feeder.diagnostics

        def truncate(message):
            message.data = bytes(message.data)[:len(message.data) // 2]

        feeder.publish_pair(left, right, (44.0, 44.0), edit=truncate)
        assert spin_until(feeder.executor, lambda: feeder.count('rejected.truncated') == 1,
                          10.0), feeder.diagnostics
        good_pair(50.0)
        assert spin_until(feeder.executor, lambda: feeder.count('rejected.dropped_unpaired') >= 2
                          and feeder.count('published') == 9, 10.0), feeder.diagnostics
        assert process.poll() is None, 'the tracker died'
    finally:
        if process.poll() is None:
            process.send_signal(signal.SIGINT)
        try:
            output, _ = process.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            process.kill()
            output, _ = process.communicate()
        feeder.executor.shutdown()
        feeder.node.destroy_node()
    assert process.returncode == 0, output
    # the two dropped images are counted (above) and logged at DEBUG only: no falling behind
    drops = [line for line in output.splitlines() if 'image dropped' in line]
    assert drops and all('[DEBUG]' in line for line in drops), output
    assert 'falling behind' not in output, output
    stamps = [p.header.stamp.sec + 1e-9 * p.header.stamp.nanosec for p in feeder.points]
    assert sorted(stamps) == sorted(truth), 'a point was published for a bad pair'
    errors = np.array([np.linalg.norm(np.array([p.point.x, p.point.y, p.point.z]) - truth[s])
                       for p, s in zip(feeder.points, stamps)])
    assert all(p.header.frame_id == 'cbha_base' for p in feeder.points)
    rms = float(np.sqrt(np.mean(errors ** 2)))
    print(f'\nstereo_tracker over DDS: {len(errors)} points, RMS {rms * 1e3:.4f} mm, '
          f'max {errors.max() * 1e3:.4f} mm; diagnostics {feeder.diagnostics}')
    assert rms <= 0.3e-3 and errors.max() <= 1.0e-3
    assert float(feeder.diagnostics['processing_median_ms']) > 0.0
