"""
Stereo calibration from checkerboard image pairs, and synthetic pairs from a known rig.

:func:`calibrate_stereo` finds the inner corners of each pair (``cv2.findChessboardCorners``,
refined by ``cv2.cornerSubPix``), calibrates each camera (``cv2.calibrateCamera``, plumb_bob),
then the pair with the intrinsics fixed (``cv2.stereoCalibrate``: rotation and translation of the
right camera) and rectifies it (``cv2.stereoRectify``, zero disparity at infinity, alpha 0): the
results are the two ROS camera models (K, D, R, P) of a
:class:`~cbha_inverse.vision.rig.StereoRig`.
:func:`render_calibration_pairs` renders checkerboard poses that a person would hold in front of a
known rig (tilted up to ~35 deg, the whole pattern in both images).
"""

from dataclasses import dataclass
from pathlib import Path

from cbha_inverse.core.so3 import so3_exp
from cbha_inverse.vision.camera import camera_model
from cbha_inverse.vision.render import CameraRenderer, render_checkerboard, RenderSettings
from cbha_inverse.vision.rig import StereoRig
from cbha_inverse.vision.stereo import project_raw
import cv2
import numpy as np

SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-4)
"""Corner refinement: at most 50 iterations, stop below 1e-4 px."""


@dataclass(frozen=True)
class StereoCalibration:
    """
    Result of a stereo calibration.

    Attributes
    ----------
    rig : StereoRig
        The calibrated cameras (``base_from_left`` as given to :func:`calibrate_stereo`).
    rms_left, rms_right : float  [px]
        RMS reprojection error of each camera's own calibration.
    rms_stereo : float  [px]
        RMS reprojection error of the stereo calibration.
    pairs_used : int
        Pairs in which both images showed the whole pattern.
    rotation : (3, 3) ndarray
        ``R`` of ``cv2.stereoCalibrate``: ``p_right = R p_left + T``.
    translation : (3,) ndarray  [m]
        ``T`` of ``cv2.stereoCalibrate``.

    """

    rig: StereoRig
    rms_left: float
    rms_right: float
    rms_stereo: float
    pairs_used: int
    rotation: np.ndarray
    translation: np.ndarray

    @property
    def baseline(self):
        """Return the distance [m] between the optical centres, ``|T|``."""
        return float(np.linalg.norm(self.translation))


def board_points(pattern, square):
    """
    Return the inner corners of a checkerboard in its own plane.

    Parameters
    ----------
    pattern : (2,) tuple of int
        Inner corners per row and per column, e.g. ``(9, 6)``.
    square : float  [m]
        Side of a square.

    Returns
    -------
    (pattern[0] * pattern[1], 3) ndarray of float32  [m]
        Corners in OpenCV's order (row by row), z = 0.

    """
    grid = np.mgrid[0:pattern[0], 0:pattern[1]].T.reshape(-1, 2)
    return np.column_stack([grid * square, np.zeros(len(grid))]).astype(np.float32)


def find_corners(image, pattern):
    """
    Find and refine the inner corners of a checkerboard.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray of uint8
        Mono or BGR image.
    pattern : (2,) tuple of int
        Inner corners per row and per column.

    Returns
    -------
    (N, 1, 2) ndarray of float32 or None  [px]
        Sub-pixel corners, or None when the whole pattern is not found.

    """
    gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    found, corners = cv2.findChessboardCorners(
        gray, tuple(pattern), flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not found:
        return None
    return cv2.cornerSubPix(gray, corners, (7, 7), (-1, -1), SUBPIX_CRITERIA)


def calibrate_stereo(pairs, pattern, square, base_from_left, names=('left', 'right')):
    """
    Calibrate a stereo pair from checkerboard images.

    Parameters
    ----------
    pairs : sequence of ((H, W) ndarray, (H, W) ndarray)
        Left and right images of each checkerboard pose (mono or BGR, uint8).
    pattern : (2,) tuple of int
        Inner corners per row and per column.
    square : float  [m]
        Side of a square.
    base_from_left : (7,) array_like
        Pose of the left camera in ``cbha_base`` to store in the rig (see
        :func:`~cbha_inverse.vision.rig.register_base_from_left`).
    names : (2,) tuple of str
        Camera names.

    Returns
    -------
    StereoCalibration
        Camera models (K, D, R, P), errors and the stereo extrinsics.

    Raises
    ------
    ValueError
        If fewer than 3 pairs show the whole pattern in both images, or the sizes differ.

    """
    objects, left_corners, right_corners = [], [], []
    size = None
    for left, right in pairs:
        if size is None:
            size = (left.shape[1], left.shape[0])
        if (left.shape[1], left.shape[0]) != size or left.shape[:2] != right.shape[:2]:
            raise ValueError('every image must have the size of the first one')
        found_left, found_right = find_corners(left, pattern), find_corners(right, pattern)
        if found_left is not None and found_right is not None:
            objects.append(board_points(pattern, square))
            left_corners.append(found_left)
            right_corners.append(found_right)
    if len(objects) < 3:
        raise ValueError(f'the whole {pattern[0]}x{pattern[1]} pattern was found in both images '
                         f'of {len(objects)} pairs; at least 3 are needed')
    rms_left, k_left, d_left, _, _ = cv2.calibrateCamera(objects, left_corners, size, None,
                                                         None)
    rms_right, k_right, d_right, _, _ = cv2.calibrateCamera(objects, right_corners, size, None,
                                                            None)
    rms_stereo, k_left, d_left, k_right, d_right, rotation, translation, _, _ = \
        cv2.stereoCalibrate(objects, left_corners, right_corners, k_left, d_left, k_right,
                            d_right, size, flags=cv2.CALIB_FIX_INTRINSIC)
    r_left, r_right, p_left, p_right, _, _, _ = cv2.stereoRectify(
        k_left, d_left, k_right, d_right, size, rotation, translation,
        flags=cv2.CALIB_ZERO_DISPARITY, alpha=0.0)
    cameras = [camera_model(size[0], size[1], 'plumb_bob', d.ravel()[:5], k, r, p, name)
               for d, k, r, p, name in ((d_left, k_left, r_left, p_left, names[0]),
                                        (d_right, k_right, r_right, p_right, names[1]))]
    return StereoCalibration(StereoRig(cameras[0], cameras[1], np.asarray(base_from_left, float)),
                             float(rms_left), float(rms_right), float(rms_stereo), len(objects),
                             np.asarray(rotation, float), np.asarray(translation, float).ravel())


def render_calibration_pairs(rig, count, pattern=(9, 6), square=0.03, seed=0,
                             settings=RenderSettings(supersample=1, noise_pool=1)):
    """
    Render checkerboard pairs of a known rig (for tests and for trying the command out).

    Parameters
    ----------
    rig : StereoRig
        The true rig.
    count : int
        Pairs to render.
    pattern : (2,) tuple of int
        Inner corners per row and per column.
    square : float  [m]
        Side of a square.
    seed : int
        Seed of the poses and the noise.
    settings : RenderSettings
        Blur and noise.

    Returns
    -------
    list of ((H, W) ndarray, (H, W) ndarray)
        Mono left/right images; every pose shows the whole board in both images.

    """
    rng = np.random.default_rng(seed)
    renderers = [CameraRenderer(camera, settings, rng) for camera in (rig.left, rig.right)]
    extent = np.array([(pattern[0] + 3) * square, (pattern[1] + 3) * square])
    corners = np.array([[0, 0, 0], [extent[0], 0, 0], [0, extent[1], 0],
                        [extent[0], extent[1], 0]], float)
    pairs = []
    while len(pairs) < count:
        tilt = so3_exp(np.concatenate([rng.uniform(-0.6, 0.6, 2), rng.uniform(-0.3, 0.3, 1)]))
        # board normal towards the cameras: its z axis points away from them (+z optical)
        rotation = tilt
        centre = np.array([rig.baseline / 2 + rng.uniform(-0.12, 0.12),
                           rng.uniform(-0.09, 0.09), rng.uniform(0.45, 0.8)])
        origin = centre - rotation[:, :2] @ (extent / 2)
        p_left = corners @ rotation.T + origin
        views = ((rig.left, p_left), (rig.right, rig.right_from_left(p_left)))
        margin = 20
        visible = all(
            np.all(frame[:, 2] > 0.1) and np.all((pixels >= margin) & (
                pixels <= [camera.width - margin, camera.height - margin]))
            for camera, frame in views for pixels in [project_raw(camera, frame)])
        if not visible:
            continue
        origin_right = rig.right_from_left(origin[None])[0]
        rotation_right = rig.right.rectification.T @ rig.left.rectification @ rotation
        pairs.append(tuple(render_checkerboard(renderer, rot, org, pattern, square)
                           for renderer, rot, org in ((renderers[0], rotation, origin),
                                                      (renderers[1], rotation_right,
                                                       origin_right))))
    return pairs


def write_pairs(folder, pairs):
    """
    Write image pairs as ``left_NNN.png`` / ``right_NNN.png``.

    Parameters
    ----------
    folder : str or os.PathLike
        Output folder (created).
    pairs : sequence of (ndarray, ndarray)
        Images.

    Returns
    -------
    pathlib.Path
        The folder.

    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for index, (left, right) in enumerate(pairs):
        cv2.imwrite(str(folder / f'left_{index:03d}.png'), left)
        cv2.imwrite(str(folder / f'right_{index:03d}.png'), right)
    return folder


def read_pairs(folder):
    """
    Read the pairs ``left_*.png`` / ``right_*.png`` of a folder (matched by their suffix).

    Parameters
    ----------
    folder : str or os.PathLike
        The folder.

    Returns
    -------
    list of (ndarray, ndarray)
        Mono images of every left image that has a right partner, in name order.

    Raises
    ------
    ValueError
        If an image cannot be read or no pair is found.

    """
    folder = Path(folder)
    pairs = []
    for left_path in sorted(folder.glob('left_*.png')):
        right_path = folder / ('right_' + left_path.name[len('left_'):])
        if not right_path.is_file():
            continue
        images = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in (left_path, right_path)]
        if any(image is None for image in images):
            raise ValueError(f'{left_path} or {right_path}: not a readable image')
        pairs.append(tuple(images))
    if not pairs:
        raise ValueError(f'{folder}: no left_*.png / right_*.png pairs')
    return pairs
