"""
A calibrated stereo rig: two ROS camera models plus the pose of the left camera in ``cbha_base``.

The two :class:`~cbha_inverse.vision.camera.CameraModel` carry the rectified stereo geometry as
ROS does: ``R_left``, ``R_right`` rotate each raw camera frame into the common rectified frame,
``P_left`` and ``P_right`` project points given in the left rectified frame, and
``P_right[0, 3] = -fx' * B``. ``base_from_left`` is the pose of the left camera's optical frame
(x right, y down, z forward) in ``cbha_base``, 7 floats ``[x, y, z, qx, qy, qz, qw]``.

Frames (pinocchio-style names): ``p_base`` points in ``cbha_base``, ``p_left`` in the left raw
optical frame, ``p_rect`` in the left rectified frame, ``p_right`` in the right raw optical frame.
The rig file (``config/cameras/rig.yaml``) names the two camera_info YAMLs and holds
``base_from_left``. No OpenCV here.
"""

from dataclasses import dataclass
from pathlib import Path

from cbha_inverse.config_files import check_keys, read_yaml
from cbha_inverse.core.so3 import matrix_from_quat, pose_vector
from cbha_inverse.errors import ConfigError
from cbha_inverse.vision.camera import camera_model, load_camera_yaml, save_camera_yaml
import numpy as np
import yaml


@dataclass(frozen=True)
class StereoRig:
    """
    Two calibrated cameras and the left camera's pose in ``cbha_base``.

    Attributes
    ----------
    left, right : CameraModel
        The cameras (rectified geometry in their R and P).
    base_from_left : (7,) ndarray  [m, -]
        ``[x, y, z, qx, qy, qz, qw]``: the left optical frame in ``cbha_base``.

    """

    left: object
    right: object
    base_from_left: np.ndarray

    def __post_init__(self):
        """Keep a read-only copy of the pose and its rotation (used for every tracked pair)."""
        pose = np.array(self.base_from_left, dtype=float)
        pose.setflags(write=False)
        rotation = matrix_from_quat(pose[3:])
        rotation.setflags(write=False)
        # frozen dataclass: the two attributes are set once, here
        object.__setattr__(self, 'base_from_left', pose)
        object.__setattr__(self, '_rotation_base_left', rotation)

    @property
    def baseline(self):
        """Return the distance [m] between the optical centres, ``-Tx_right / fx_right``."""
        return self.right.baseline_offset - self.left.baseline_offset

    @property
    def rotation_base_left(self):
        """Return ``R_base_left`` (3, 3, read-only): the left optical axes in ``cbha_base``."""
        return self._rotation_base_left

    def left_from_base(self, p_base):
        """
        Express points of ``cbha_base`` in the left raw optical frame.

        Parameters
        ----------
        p_base : (N, 3) array_like  [m]
            Points in ``cbha_base``.

        Returns
        -------
        (N, 3) ndarray  [m]
            ``p_left = R_base_leftᵀ (p_base - t_base_left)``.

        """
        p_base = np.atleast_2d(np.asarray(p_base, dtype=float))
        return (p_base - self.base_from_left[:3]) @ self.rotation_base_left

    def base_from_left_points(self, p_left):
        """
        Express points of the left raw optical frame in ``cbha_base``.

        Parameters
        ----------
        p_left : (N, 3) array_like  [m]
            Points in the left optical frame.

        Returns
        -------
        (N, 3) ndarray  [m]
            ``p_base = R_base_left p_left + t_base_left``.

        """
        p_left = np.atleast_2d(np.asarray(p_left, dtype=float))
        return p_left @ self.rotation_base_left.T + self.base_from_left[:3]

    def right_from_left(self, p_left):
        """
        Express points of the left raw optical frame in the right raw optical frame.

        Parameters
        ----------
        p_left : (N, 3) array_like  [m]
            Points in the left optical frame.

        Returns
        -------
        (N, 3) ndarray  [m]
            ``p_right = R_rightᵀ (R_left p_left - [B, 0, 0])`` (ROS rectified stereo geometry).

        """
        p_left = np.atleast_2d(np.asarray(p_left, dtype=float))
        p_rect = p_left @ self.left.rectification.T
        p_rect_right = p_rect - np.array([self.baseline, 0.0, 0.0])
        return p_rect_right @ self.right.rectification

    def camera_poses(self):
        """
        Return the poses of the two raw optical frames in ``cbha_base``.

        Returns
        -------
        dict
            ``{'left': (7,) ndarray, 'right': (7,) ndarray}``, ``[x, y, z, qx, qy, qz, qw]``
            [m, -]: ``base_from_left``, and the right frame from the rectified geometry of
            :meth:`right_from_left` inverted, ``R_base_right = R_base_left R_leftᵀ R_right``,
            ``t_base_right = t_base_left + R_base_left R_leftᵀ [B, 0, 0]``.

        """
        base_from_rect = self.rotation_base_left @ self.left.rectification.T
        rotation = base_from_rect @ self.right.rectification
        translation = self.base_from_left[:3] + base_from_rect @ np.array([self.baseline, 0., 0.])
        return {'left': self.base_from_left.copy(), 'right': pose_vector(rotation, translation)}


def check_pose(pose):
    """
    Validate a ``[x, y, z, qx, qy, qz, qw]`` pose and return it with a unit quaternion.

    Parameters
    ----------
    pose : (7,) array_like
        The pose.

    Returns
    -------
    (7,) ndarray
        The pose, quaternion normalised.

    Raises
    ------
    ValueError
        If it is not 7 finite numbers or its quaternion is (near) zero.

    """
    try:
        pose = np.asarray(pose, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f'must be 7 numbers [x, y, z, qx, qy, qz, qw], got {pose!r}') from None
    if pose.size != 7 or not np.all(np.isfinite(pose)):
        raise ValueError(f'must be 7 finite numbers [x, y, z, qx, qy, qz, qw], got '
                         f'{pose.tolist()}')
    norm = np.linalg.norm(pose[3:])
    if norm < 1e-6:
        raise ValueError('the quaternion (qx, qy, qz, qw) must not be zero')
    return np.concatenate([pose[:3], pose[3:] / norm])


def parallel_rig(width, height, focal_length, baseline, base_from_left, distortion=None,
                 distortion_model='plumb_bob', principal_offset=(0.0, 0.0)):
    """
    Build a rig of two identical, parallel cameras (already rectified: ``R = I``).

    Parameters
    ----------
    width, height : int  [px]
        Image size.
    focal_length : float  [px]
        ``fx = fy``.
    baseline : float  [m]
        Distance of the right camera along the left camera's x axis.
    base_from_left : (7,) array_like
        Left optical frame in ``cbha_base``.
    distortion : array_like, optional
        ``D`` of both raw images (default: none).
    distortion_model : str
        ``plumb_bob`` or ``rational_polynomial``.
    principal_offset : (2,) array_like  [px]
        Principal point offset from the image centre.

    Returns
    -------
    StereoRig
        The rig.

    """
    size = 5 if distortion_model == 'plumb_bob' else 8
    coefficients = np.zeros(size) if distortion is None else np.asarray(distortion, float)
    cx = (width - 1) / 2.0 + principal_offset[0]
    cy = (height - 1) / 2.0 + principal_offset[1]
    k_matrix = np.array([[focal_length, 0.0, cx], [0.0, focal_length, cy], [0.0, 0.0, 1.0]])
    p_left = np.hstack([k_matrix, np.zeros((3, 1))])
    p_right = p_left.copy()
    p_right[0, 3] = -focal_length * baseline
    cameras = [camera_model(width, height, distortion_model, coefficients, k_matrix, np.eye(3),
                            projection, name)
               for projection, name in ((p_left, 'left'), (p_right, 'right'))]
    return StereoRig(cameras[0], cameras[1], check_pose(base_from_left))


def load_rig(path):
    """
    Read a rig file: two camera_info YAMLs (paths relative to the file) and ``base_from_left``.

    Parameters
    ----------
    path : str or os.PathLike
        The rig YAML (keys ``left_camera_info``, ``right_camera_info``, ``base_from_left``).

    Returns
    -------
    StereoRig
        The rig.

    Raises
    ------
    ConfigError
        ``<file>: <key>: <problem>`` for a missing or bad entry (or a bad camera file).

    """
    path = Path(path)
    document = read_yaml(path)
    check_keys(path, document, ('left_camera_info', 'right_camera_info', 'base_from_left'))
    cameras = []
    for key in ('left_camera_info', 'right_camera_info'):
        if not isinstance(document.get(key), str):
            raise ConfigError(path, key, 'missing: the path of a camera_info YAML')
        cameras.append(load_camera_yaml(path.parent / document[key]))
    try:
        pose = check_pose(document.get('base_from_left'))
    except ValueError as exc:
        raise ConfigError(path, 'base_from_left', str(exc)) from None
    return StereoRig(cameras[0], cameras[1], pose)


def save_rig(folder, rig, stem=''):
    """
    Write ``<stem>left.yaml``, ``<stem>right.yaml`` and ``<stem>rig.yaml`` into a folder.

    Parameters
    ----------
    folder : str or os.PathLike
        Output folder (created).
    rig : StereoRig
        The rig.
    stem : str
        File name prefix.

    Returns
    -------
    pathlib.Path
        The rig file.

    """
    folder = Path(folder)
    save_camera_yaml(folder / f'{stem}left.yaml', rig.left)
    save_camera_yaml(folder / f'{stem}right.yaml', rig.right)
    document = {'left_camera_info': f'{stem}left.yaml', 'right_camera_info': f'{stem}right.yaml',
                'base_from_left': [float(v) for v in rig.base_from_left]}
    path = folder / f'{stem}rig.yaml'
    path.write_text(yaml.safe_dump(document, sort_keys=False, default_flow_style=None))
    return path


def register_base_from_left(p_left, p_base):
    """
    Find ``base_from_left`` from points known in both frames (Kabsch, least squares).

    Parameters
    ----------
    p_left : (N, 3) array_like  [m]
        Points tracked in the left optical frame (N >= 3, not collinear).
    p_base : (N, 3) array_like  [m]
        The same points in ``cbha_base``.

    Returns
    -------
    pose : (7,) ndarray
        ``base_from_left`` minimising ``sum |R p_left + t - p_base|²``.
    rms : float  [m]
        Residual RMS of the fit.

    Raises
    ------
    ValueError
        With fewer than 3 points, mismatched shapes, non-finite values or collinear points.

    """
    p_left = np.asarray(p_left, dtype=float)
    p_base = np.asarray(p_base, dtype=float)
    if p_left.shape != p_base.shape or p_left.ndim != 2 or p_left.shape[1] != 3:
        raise ValueError(f'need two (N, 3) arrays, got {p_left.shape} and {p_base.shape}')
    if p_left.shape[0] < 3:
        raise ValueError(f'need at least 3 points, got {p_left.shape[0]}')
    if not (np.all(np.isfinite(p_left)) and np.all(np.isfinite(p_base))):
        raise ValueError('points must be finite')
    mean_left, mean_base = p_left.mean(axis=0), p_base.mean(axis=0)
    centred_left, centred_base = p_left - mean_left, p_base - mean_base
    singular = np.linalg.svd(centred_left, compute_uv=False)
    if singular[1] <= 1e-9 * max(singular[0], 1e-300):
        raise ValueError('the points are collinear: the rotation is not determined')
    u_matrix, _, vt_matrix = np.linalg.svd(centred_left.T @ centred_base)
    sign = np.sign(np.linalg.det(vt_matrix.T @ u_matrix.T)) or 1.0
    rotation = vt_matrix.T @ np.diag([1.0, 1.0, sign]) @ u_matrix.T
    translation = mean_base - rotation @ mean_left
    residual = p_left @ rotation.T + translation - p_base
    return pose_vector(rotation, translation), float(np.sqrt(np.mean(np.sum(residual ** 2, 1))))
