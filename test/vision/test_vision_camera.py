"""Camera models, camera_info YAML files, the rig and base_from_left registration."""

import re

from cbha_inverse.core.so3 import matrix_from_quat, so3_exp
from cbha_inverse.errors import ConfigError
from cbha_inverse.paths import config_path
from cbha_inverse.vision.camera import (
    camera_from_yaml, camera_model, camera_to_yaml, load_camera_yaml, save_camera_yaml)
from cbha_inverse.vision.rig import (
    load_rig, parallel_rig, pose_vector, register_base_from_left, save_rig, StereoRig)
import numpy as np
import pytest

# As written by the ROS camera_calibration tool (its documentation's narrow_stereo example).
ROS_CALIBRATION_FILE = """image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [ 635.82306,    0.     ,  310.60519,
            0.     ,  636.47076,  238.82049,
            0.     ,    0.     ,    1.     ]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.004584, 0.006119, -0.000717, -0.004043, 0.000000]
rectification_matrix:
  rows: 3
  cols: 3
  data: [ 1.,  0.,  0.,
          0.,  1.,  0.,
          0.,  0.,  1.]
projection_matrix:
  rows: 3
  cols: 4
  data: [ 634.99542,    0.     ,  306.58032,    0.     ,
            0.     ,  635.91656,  238.39091,    0.     ,
            0.     ,    0.     ,    1.     ,    0.     ]
"""


def test_ros_calibration_file_loads_unchanged():
    """A file of the ROS camera_calibration tool gives its numbers, in CameraInfo layout."""
    camera = camera_from_yaml(ROS_CALIBRATION_FILE)
    assert (camera.width, camera.height, camera.name) == (640, 480, 'narrow_stereo')
    assert camera.distortion_model == 'plumb_bob'
    assert camera.camera_matrix[0, 0] == 635.82306 and camera.camera_matrix[1, 2] == 238.82049
    assert camera.distortion.tolist() == [-0.004584, 0.006119, -0.000717, -0.004043, 0.0]
    assert np.array_equal(camera.rectification, np.eye(3))
    assert camera.projection.shape == (3, 4) and camera.projection[0, 2] == 306.58032


@pytest.mark.parametrize('model, size', [('plumb_bob', 5), ('rational_polynomial', 8)])
def test_yaml_round_trip_is_exact(tmp_path, model, size):
    """Write -> read gives the same camera, bit for bit, for both distortion models."""
    rng = np.random.default_rng(3)
    rotation = so3_exp(rng.normal(0.0, 0.05, 3))
    k_matrix = np.array([[1401.3, 0.0, 640.2], [0.0, 1399.1, 511.7], [0.0, 0.0, 1.0]])
    projection = np.hstack([k_matrix, [[-168.1], [0.0], [0.0]]])
    camera = camera_model(1280, 1024, model, rng.normal(0.0, 0.01, size), k_matrix, rotation,
                          projection, 'right')
    path = save_camera_yaml(tmp_path / 'right.yaml', camera)
    again = load_camera_yaml(path)
    assert (again.width, again.height, again.name, again.distortion_model) == (
        1280, 1024, 'right', model)
    for field in ('distortion', 'camera_matrix', 'rectification', 'projection'):
        assert np.array_equal(getattr(again, field), getattr(camera, field)), field
    assert camera_to_yaml(again) == path.read_text()


@pytest.mark.parametrize('edit, key', [
    (lambda s: s.replace('cols: 5', 'cols: 4'), 'distortion_coefficients'),
    (lambda s: s.replace('plumb_bob', 'fisheye'), 'distortion_model'),
    (lambda s: s.replace('image_width: 640\n', ''), 'image_width'),
    (lambda s: s.replace('635.82306', '-635.82306'), 'camera_matrix'),
    (lambda s: s.replace('data: [ 1.,  0.,', 'data: [ 2.,  0.,'), 'rectification_matrix'),
    (lambda s: re.sub(r'camera_matrix:\n(  .*\n)+', 'camera_matrix: [1, 2]\n', s),
     'camera_matrix'),
    (lambda s: s.replace('camera_matrix:', 'camera_matrix: [1, 2]\nx:'), 'x'),
    (lambda s: s.replace('rows: 3\n  cols: 4', 'rows: 3\n  cols: 3'), 'projection_matrix'),
    (lambda s: s.replace('image_height: 480', 'image_height: [480'), 'line 3'),
])
def test_broken_camera_file_names_file_and_key(tmp_path, edit, key):
    """A broken camera YAML gives one ConfigError line naming the file and the key."""
    path = tmp_path / 'broken.yaml'
    path.write_text(edit(ROS_CALIBRATION_FILE))
    with pytest.raises(ConfigError) as error:
        load_camera_yaml(path)
    assert error.value.path == str(path), str(error.value)
    assert error.value.key.split('.')[0] == key, str(error.value)
    assert '\n' not in str(error.value)


def test_missing_camera_file_is_a_config_error(tmp_path):
    """A camera file that does not exist is reported, not a traceback."""
    with pytest.raises(ConfigError, match='file: no such file'):
        load_camera_yaml(tmp_path / 'absent.yaml')


def test_default_rig_geometry():
    """The default rig: 0.12 m baseline, looking along -x of cbha_base at the workspace centre."""
    rig = load_rig(config_path('cameras', 'rig.yaml'))
    assert rig.baseline == pytest.approx(0.12)
    assert (rig.left.width, rig.left.height) == (1280, 1024)
    centre = np.array([0.2308, 0.0, -0.0292])
    p_left = rig.left_from_base(centre)[0]
    assert p_left == pytest.approx([0.06, 0.0, 0.6])
    p_right = rig.right_from_left(p_left)[0]
    assert p_right == pytest.approx([-0.06, 0.0, 0.6])
    assert rig.base_from_left_points(p_left)[0] == pytest.approx(centre)
    demo = load_rig(config_path('cameras', 'demo_rig.yaml'))
    assert np.array_equal(demo.base_from_left, rig.base_from_left)
    assert demo.left.camera_matrix[0, 0] == pytest.approx(0.5 * rig.left.camera_matrix[0, 0])


def test_camera_poses_map_each_optical_frame_into_cbha_base():
    """The two poses of camera_poses() carry right-frame points where the rig's geometry does."""
    rng = np.random.default_rng(4)
    k_matrix = np.array([[1400.0, 0.0, 640.0], [0.0, 1400.0, 512.0], [0.0, 0.0, 1.0]])
    p_left = np.hstack([k_matrix, np.zeros((3, 1))])
    p_right = p_left.copy()
    p_right[0, 3] = -1400.0 * 0.15
    cameras = [camera_model(1280, 1024, 'plumb_bob', np.zeros(5), k_matrix, so3_exp(rotvec),
                            projection, name) for rotvec, projection, name in (
        ([0.02, -0.01, 0.005], p_left, 'left'), ([-0.01, 0.03, 0.0], p_right, 'right'))]
    rig = StereoRig(cameras[0], cameras[1], pose_vector(so3_exp([0.4, -1.0, 2.2]),
                                                        [0.7, -0.1, 0.05]))
    poses = rig.camera_poses()
    np.testing.assert_array_equal(poses['left'], rig.base_from_left)
    points_left = rng.uniform(-0.2, 0.2, (20, 3)) + [0.0, 0.0, 0.6]
    points_right = rig.right_from_left(points_left)
    rotation, translation = matrix_from_quat(poses['right'][3:]), poses['right'][:3]
    np.testing.assert_allclose(points_right @ rotation.T + translation,
                               rig.base_from_left_points(points_left), atol=1e-14)
    # the default rig: parallel cameras, the right one 0.12 m along +y of cbha_base
    default = load_rig(config_path('cameras', 'rig.yaml')).camera_poses()
    np.testing.assert_allclose(default['right'], [0.8308, 0.06, -0.0292, -0.5, -0.5, 0.5, 0.5],
                               atol=1e-14)


def test_rig_keeps_its_own_read_only_pose():
    """The rig copies its pose: changing the caller's array later moves no tracked point."""
    pose = pose_vector(so3_exp([0.1, 0.2, -0.3]), [0.5, 0.0, 0.1])
    rig = StereoRig(None, None, pose)
    point = rig.base_from_left_points([0.0, 0.0, 1.0])
    pose[:] = [9.0, 9.0, 9.0, 0.0, 0.0, 0.0, 1.0]
    np.testing.assert_array_equal(rig.base_from_left_points([0.0, 0.0, 1.0]), point)
    np.testing.assert_allclose(point[0], so3_exp([0.1, 0.2, -0.3])[:, 2] + [0.5, 0.0, 0.1],
                               atol=1e-15)
    with pytest.raises(ValueError):
        rig.base_from_left[0] = 1.0


def test_rig_round_trip_and_broken_pose(tmp_path):
    """save_rig -> load_rig is exact; a bad base_from_left names the key."""
    rig = load_rig(config_path('cameras', 'rig.yaml'))
    path = save_rig(tmp_path, rig, stem='copy_')
    again = load_rig(path)
    assert np.array_equal(again.base_from_left, rig.base_from_left)
    assert np.array_equal(again.right.projection, rig.right.projection)
    path.write_text(path.read_text().replace('base_from_left: [', 'base_from_left: [1.0, '))
    with pytest.raises(ConfigError) as error:
        load_rig(path)
    assert error.value.key == 'base_from_left'


def test_kabsch_registration_recovers_a_known_pose():
    """Points seen in the camera and known in cbha_base give the pose back (noise-free: exact)."""
    rng = np.random.default_rng(7)
    truth = pose_vector(so3_exp([0.3, -1.2, 2.0]), [0.8, -0.05, 0.02])
    rig = parallel_rig(640, 480, 600.0, 0.1, truth)
    p_base = rng.uniform([0.1, -0.1, -0.1], [0.3, 0.1, 0.1], (5, 3))
    p_left = rig.left_from_base(p_base)
    pose, rms = register_base_from_left(p_left, p_base)
    assert rms < 1e-12
    assert pose[:3] == pytest.approx(truth[:3], abs=1e-12)
    assert np.allclose(matrix_from_quat(pose[3:]), matrix_from_quat(truth[3:]), atol=1e-12)
    noisy_pose, noisy_rms = register_base_from_left(
        p_left + rng.normal(0.0, 2e-4, p_left.shape), p_base)
    assert 0.0 < noisy_rms < 1e-3
    assert np.linalg.norm(noisy_pose[:3] - truth[:3]) < 2e-3
    with pytest.raises(ValueError, match='collinear'):
        line = np.outer(np.arange(4.0), [0.1, 0.0, 0.0])
        register_base_from_left(line, line)
    with pytest.raises(ValueError, match='at least 3'):
        register_base_from_left(p_left[:2], p_base[:2])
