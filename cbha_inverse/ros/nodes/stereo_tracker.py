"""
``stereo_tracker``: the tip position from two calibrated cameras (``docs/cameras.md``).

Subscribes ``stereo/left/image_raw`` and ``stereo/right/image_raw`` (sensor_msgs/Image ``mono8``,
``bgr8`` or ``rgb8``; RELIABLE, keep-last ``image_depth`` by default: large images lose fragments
over best effort; ``image_reliability: best_effort`` as the option) and
``stereo/{left,right}/camera_info``. The camera models come from the camera_info topics as soon as
one arrives; until then from the camera_info YAML files of the params file (the fallback).
``base_from_left`` is a parameter. Images are paired by header stamp within
``max_pair_dt`` (bounded queues: the oldest is dropped and counted); each pair goes through
:class:`cbha_inverse.vision.tracking.StereoTracker` and a good point is published on
``tip/measured`` (PointStamped in ``frame_id``, stamp = the pair's left stamp, sensor-data QoS).
A pair without a valid marker publishes nothing (WARN, throttled) and counts its reason in
``/diagnostics`` with the detection rate, epipolar and reprojection errors, processing time and
input frame rate. The detection and rejection thresholds (``marker.*``, the error and depth
limits), ``max_pair_dt`` and ``log_throttle`` are live (``set_parameters``, checked as at start);
the cameras, the pose, the frame and the QoS are fixed at start. The two optical frames of the
rig (``base_from_left`` and the camera models) are latched on ``/tf_static``
(``publish_camera_tf``; :mod:`cbha_inverse.ros.common.tf`).
"""

import collections
from dataclasses import dataclass
import math
import sys
import time

from cbha_inverse.errors import ConfigError
from cbha_inverse.paths import config_path
from cbha_inverse.ros.common.conversions import point_stamped, stamp_seconds
from cbha_inverse.ros.common.diagnostics import (DiagnosticsPublisher, make_status, OK,
                                                 TimingStats, WARN)
from cbha_inverse.ros.common.images import camera_from_info, image_array, ImageRejected
from cbha_inverse.ros.common.params import declare_parameters, param, ParameterError
from cbha_inverse.ros.common.qos import MEASURED_QOS
from cbha_inverse.ros.common.rejections import Rejections, ThrottledLog
from cbha_inverse.ros.common.runner import run_node
from cbha_inverse.ros.common.tf import camera_frame, make_broadcaster
from cbha_inverse.vision.camera import load_camera_yaml
from cbha_inverse.vision.marker import MarkerParams
from cbha_inverse.vision.pairing import DropMonitor, SIDES, StereoPairer
from cbha_inverse.vision.rig import check_pose, StereoRig
from cbha_inverse.vision.stereo import StereoLimits
from cbha_inverse.vision.tracking import StereoTracker
from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image

NODE_NAME = 'stereo_tracker'


@dataclass(frozen=True)
class StereoTrackerParams:
    """Parameters of the ``stereo_tracker`` node."""

    left_camera_info_file: str = param(
        'cameras/left.yaml', 'fallback camera_info YAML of the left camera until the topic '
        'delivers one: a path, or relative to config/ ("" = wait for the topic)')
    right_camera_info_file: str = param(
        'cameras/right.yaml', 'fallback camera_info YAML of the right camera')
    base_from_left: tuple = param(
        (0.8308, -0.06, -0.0292, -0.5, -0.5, 0.5, 0.5),
        'pose of the left optical frame in frame_id, [x, y, z, qx, qy, qz, qw] [m]')
    frame_id: str = param('cbha_base', 'frame_id of the published tip')
    publish_camera_tf: bool = param(True, 'latch the optical frames (stereo_left_optical, '
                                    'stereo_right_optical) in frame_id on /tf_static')
    max_pair_dt: float = param(0.002, 'largest stamp difference of a left/right pair [s]',
                               low=0.0, high=1.0, live=True)
    queue_size: int = param(4, 'images kept per camera while waiting for a partner', low=1,
                            high=100)
    image_reliability: str = param('reliable', 'QoS reliability of the image subscriptions',
                                   choices=('reliable', 'best_effort'))
    image_depth: int = param(2, 'QoS depth (keep-last) of the image subscriptions', low=1,
                             high=100)
    marker_kind: str = param('sphere', 'marker: red sphere or ArUco tag',
                             choices=('sphere', 'aruco'), ros_name='marker.kind', live=True)
    hue_max_low: int = param(10, 'red hue band 1: [0, this] (OpenCV hue 0..179)', low=0,
                             high=179, ros_name='marker.hue_max_low', live=True)
    hue_min_high: int = param(170, 'red hue band 2: [this, 179]', low=0, high=179,
                              ros_name='marker.hue_min_high', live=True)
    saturation_min: int = param(120, 'least saturation of a marker pixel', low=0, high=255,
                                ros_name='marker.saturation_min', live=True)
    value_min: int = param(60, 'least value of a marker pixel', low=0, high=255,
                           ros_name='marker.value_min', live=True)
    mono_threshold: int = param(200, 'mono8 images: least brightness of a marker pixel', low=0,
                                high=255, ros_name='marker.mono_threshold', live=True)
    min_area: float = param(20.0, 'least blob area [px^2]', low=0.0, high=1.0e7,
                            ros_name='marker.min_area', live=True)
    max_area: float = param(20000.0, 'largest blob area [px^2]', low=0.0, high=1.0e7,
                            ros_name='marker.max_area', live=True)
    min_circularity: float = param(0.75, 'least 4 pi A / P^2 of a blob', low=0.0, high=1.0,
                                   ros_name='marker.min_circularity', live=True)
    ambiguity_ratio: float = param(0.3, 'second / best blob score above which an image is '
                                   'ambiguous', low=0.0, high=1.0,
                                   ros_name='marker.ambiguity_ratio', live=True)
    window: int = param(48, 'half size of the search window around the last detection [px] '
                        '(0 = full frame always)', low=0, high=10000, ros_name='marker.window',
                        live=True)
    aruco_dictionary: str = param('DICT_4X4_50', 'cv2.aruco predefined dictionary',
                                  ros_name='marker.aruco_dictionary', live=True)
    aruco_id: int = param(0, 'ArUco tag id of the marker', low=0, high=100000,
                          ros_name='marker.aruco_id', live=True)
    coarse_step: int = param(2, 'full-frame search: subsampling step of the first pass '
                             '(1 = none)', low=1, high=8, ros_name='marker.coarse_step', live=True)
    max_epipolar_error: float = param(2.0, 'largest |v_left - v_right| after rectification '
                                      '[px]', low=0.0, high=1000.0, live=True)
    max_reprojection_error: float = param(1.5, 'largest reprojection error [px]', low=0.0,
                                          high=1000.0, live=True)
    min_depth: float = param(0.2, 'least depth in the left camera [m]', low=0.0, high=100.0,
                             live=True)
    max_depth: float = param(2.0, 'largest depth in the left camera [m]', low=0.0, high=100.0,
                             live=True)
    diagnostics_period: float = param(1.0, 'period of /diagnostics [s]', low=0.05, high=60.0)
    log_throttle: float = param(1.0, 'least time between two logs of one kind [s]', low=0.0,
                                high=3600.0, live=True)


def detection(p):
    """
    Return the marker detection and the stereo rejection limits of the node's parameters.

    Parameters
    ----------
    p : StereoTrackerParams
        The parameters (at start and on every live change).

    Returns
    -------
    marker : cbha_inverse.vision.marker.MarkerParams
    limits : cbha_inverse.vision.stereo.StereoLimits

    Raises
    ------
    ValueError
        If an area or depth range is empty.

    """
    if p.min_area > p.max_area:
        raise ValueError(f'marker.min_area {p.min_area:g} px^2 is above marker.max_area '
                         f'{p.max_area:g} px^2')
    if p.min_depth >= p.max_depth:
        raise ValueError(f'min_depth {p.min_depth:g} m must be below max_depth '
                         f'{p.max_depth:g} m')
    marker = MarkerParams(
        kind=p.marker_kind, hue_max_low=p.hue_max_low, hue_min_high=p.hue_min_high,
        saturation_min=p.saturation_min, value_min=p.value_min, mono_threshold=p.mono_threshold,
        min_area=p.min_area, max_area=p.max_area, min_circularity=p.min_circularity,
        ambiguity_ratio=p.ambiguity_ratio, window=p.window, aruco_dictionary=p.aruco_dictionary,
        aruco_id=p.aruco_id, coarse_step=p.coarse_step)
    limits = StereoLimits(p.max_epipolar_error, p.max_reprojection_error, p.min_depth,
                          p.max_depth)
    return marker, limits


def _camera_file(name):
    if not name:
        return None
    path = config_path(name)
    return path if path.is_file() else name


class StereoTrackerNode(Node):
    """
    Stereo tip tracker: two image streams in, ``tip/measured`` out.

    Parameters
    ----------
    **kwargs
        Passed to ``rclpy.node.Node``.

    Raises
    ------
    ParameterError
        On invalid parameters or an unreadable camera_info file.

    """

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        try:
            self.params = declare_parameters(self, StereoTrackerParams, self._apply_parameters)
            p = self.params
            self.pose = check_pose(p.base_from_left)
            self.marker, self.limits = detection(p)
            self.cameras = {}
            for side, name in zip(SIDES, (p.left_camera_info_file, p.right_camera_info_file)):
                path = _camera_file(name)
                if path is not None:
                    self.cameras[side] = (load_camera_yaml(path), f'file {path}')
            # after the camera files: a broken one is the only line, without TF's INFO before it
            self.camera_tf = make_broadcaster(self, static=True) if p.publish_camera_tf else None
            self.tracker = None
            self._rebuild_tracker()
        except ConfigError:  # a camera file: its own one-line message names file and key
            self.destroy_node()
            raise
        except ValueError as exc:
            self.destroy_node()
            raise ParameterError(str(exc)) from None
        self.pairer = StereoPairer(p.max_pair_dt, p.queue_size)
        self.drops = DropMonitor()
        self.log = ThrottledLog(self.get_logger(), lambda: self.params.log_throttle)
        self.counts = Rejections(self.log)
        self.pairs = 0
        self.published = 0
        self.epipolar = collections.deque(maxlen=500)
        self.reprojection = collections.deque(maxlen=500)
        self.processing = TimingStats()
        self.arrivals = collections.deque(maxlen=200)
        self.last_reason = None
        image_qos = QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=p.image_depth,
            reliability=(ReliabilityPolicy.RELIABLE if p.image_reliability == 'reliable'
                         else ReliabilityPolicy.BEST_EFFORT))
        self.publisher = self.create_publisher(PointStamped, 'tip/measured', MEASURED_QOS)
        for side in SIDES:
            self.create_subscription(Image, f'stereo/{side}/image_raw',
                                     lambda message, s=side: self._on_image(s, message),
                                     image_qos)
            self.create_subscription(CameraInfo, f'stereo/{side}/camera_info',
                                     lambda message, s=side: self._on_camera_info(s, message),
                                     10)
        self.diagnostics = DiagnosticsPublisher(self, self._statuses, p.diagnostics_period)
        sources = ', '.join(f'{side}: {self.cameras[side][1]}' for side in self.cameras) or \
            'none yet (waiting for camera_info)'
        self.get_logger().info(
            f'marker {p.marker_kind}, pairs within {p.max_pair_dt * 1e3:g} ms, images '
            f'{p.image_reliability}, camera models: {sources}')

    # inputs ---------------------------------------------------------------------------------
    def _make_tracker(self, marker, limits):
        """Return the tracker of both camera models (None while one is missing)."""
        if not all(side in self.cameras for side in SIDES):
            return None
        rig = StereoRig(self.cameras['left'][0], self.cameras['right'][0], self.pose)
        return StereoTracker(rig, marker, limits)

    def _rebuild_tracker(self):
        self.tracker = self._make_tracker(self.marker, self.limits)
        if self.tracker is not None and self.camera_tf is not None:
            poses = self.tracker.rig.camera_poses()
            self.camera_tf.send(self.params.frame_id, [camera_frame(s) for s in SIDES],
                                [poses[s] for s in SIDES])

    def _apply_parameters(self, old, new):
        """Apply a change of the live parameters (checked; a ``ValueError`` refuses it)."""
        marker, limits = detection(new)
        if (marker, limits) != (self.marker, self.limits):
            # an unknown ArUco dictionary raises here, before anything changes
            self.tracker = self._make_tracker(marker, limits)
            self.marker, self.limits = marker, limits
        self.pairer.max_dt = new.max_pair_dt
        self.params = new

    def _on_camera_info(self, side, message):
        try:
            camera = camera_from_info(message)
        except ValueError as exc:
            self.counts.count('camera_info_invalid', f'rejected {side} camera_info: {exc}')
            return
        current = self.cameras.get(side)
        if current is not None and current[1] == 'topic' and _same_camera(current[0], camera):
            return
        self.cameras[side] = (camera, 'topic')
        self._rebuild_tracker()

    def _on_image(self, side, message):
        self.arrivals.append((side, time.monotonic()))
        camera = self.cameras.get(side)
        if camera is None:
            self.counts.count('no_camera_model', f'{side} image before any camera model')
            return
        try:
            pixels, order = image_array(message, camera[0].width, camera[0].height)
        except ImageRejected as exc:
            self.counts.count(exc.reason, f'rejected {side} image: {exc}')
            return
        pair, dropped = self.pairer.add(side, stamp_seconds(message.header.stamp),
                                        (pixels, order, message.header.stamp))
        # dropped images: counted (diagnostics), DEBUG; WARN only when the tracker falls behind
        self.counts.count('dropped_unpaired', None, len(dropped))
        for reason in dropped:
            self.get_logger().debug(f'{side} image dropped: no partner within '
                                    f'{self.params.max_pair_dt * 1e3:g} ms' if reason ==
                                    'no_partner' else 'image dropped: a newer pair was complete')
        if self.drops.add(len(dropped)):
            events, total = self.drops.events, self.counts['dropped_unpaired']
            self.log.warning('falling_behind', f'falling behind: {sum(events)} of the last '
                             f'{len(events)} images dropped unpaired (total {total})')
        if pair is not None:
            self._process(*pair)

    def _process(self, left, right):
        start = time.perf_counter()
        if self.tracker is None:
            self.counts.count('no_camera_model', 'image pair before both camera models')
            return
        if left[1] != right[1]:
            self.counts.count('encoding_mismatch',
                              'left and right images have different encodings')
            return
        result = self.tracker.track(left[0], right[0], left[1])
        self.pairs += 1
        self.last_reason = result.reason
        if math.isfinite(result.epipolar_error):
            self.epipolar.append(result.epipolar_error)
            self.reprojection.append(result.reprojection_error)
        if result.ok and np.all(np.isfinite(result.p_base)):
            self.publisher.publish(point_stamped(result.p_base, left[2], self.params.frame_id))
            self.published += 1
        else:
            self.counts.count(result.reason, f'no tip published: {result.reason}')
        self.processing.add(time.perf_counter() - start)

    # diagnostics ----------------------------------------------------------------------------
    def _input_rate(self):
        stamps = [t for side, t in self.arrivals if side == 'left']
        if len(stamps) < 2 or stamps[-1] <= stamps[0]:
            return 0.0
        return (len(stamps) - 1) / (stamps[-1] - stamps[0])

    def _statuses(self):
        rate = self.published / self.pairs if self.pairs else math.nan
        values = {'pairs': self.pairs, 'published': self.published, 'detection_rate': rate,
                  **self.counts.key_values(),
                  'epipolar_error_median_px': (float(np.median(self.epipolar))
                                               if self.epipolar else math.nan),
                  'reprojection_error_median_px': (float(np.median(self.reprojection))
                                                   if self.reprojection else math.nan),
                  **self.processing.summary('processing'),
                  'input_rate_hz': self._input_rate(),
                  'camera_models': ', '.join(f'{s}: {self.cameras[s][1]}'
                                             for s in self.cameras) or 'none'}
        lost = self.last_reason not in (None, 'ok')
        level = WARN if lost or self.tracker is None else OK
        message = ('no camera model' if self.tracker is None else
                   f'no marker: {self.last_reason}' if lost else
                   'waiting for images' if not self.pairs else 'tracking')
        return [make_status(self.get_name(), 'tracking', level, message, values)]


def _same_camera(first, second):
    return all(np.array_equal(getattr(first, f), getattr(second, f)) for f in (
        'distortion', 'camera_matrix', 'rectification', 'projection')) and (
        first.width, first.height) == (second.width, second.height)


def main(argv=None):
    """
    Run the ``stereo_tracker`` node until SIGINT/SIGTERM.

    Parameters
    ----------
    argv : list of str, optional
        Command line (default ``sys.argv``), e.g. ``['stereo_tracker', '--ros-args',
        '--params-file', 'config/stereo_tracker.yaml', '-r', '__ns:=/cbha']``.

    Returns
    -------
    int
        0 on a clean shutdown, 2 on invalid parameters or camera files.

    """
    return run_node(StereoTrackerNode, NODE_NAME, argv, params_class=StereoTrackerParams)


if __name__ == '__main__':
    sys.exit(main())
