"""
Stereo triangulation of one marker: rectify the two centroids, triangulate, check, go to base.

The raw centroids are undistorted and rectified with each camera's K, D, R and P
(``cv2.undistortPoints``), triangulated with the two rectified projections
(``cv2.triangulatePoints``, the point comes out in the left rectified frame), checked against
three limits and expressed in ``cbha_base`` through ``R_leftᵀ`` and ``base_from_left``:

- epipolar error: ``|v_left - v_right|`` of the rectified centroids [px] (0 for a perfect pair);
- reprojection error: the larger distance between a rectified centroid and the reprojection of
  the triangulated point with its ``P`` [px];
- depth: z of the point in the left rectified frame [m], inside ``[min_depth, max_depth]``.
"""

from dataclasses import dataclass

import cv2
import numpy as np

UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-10)
"""Iterations of the point undistortion (the default 5 leave ~0.05 px at the image corners)."""


@dataclass(frozen=True)
class StereoLimits:
    """
    Rejection limits of a triangulated marker.

    Attributes
    ----------
    max_epipolar_error : float  [px]
        Largest ``|v_left - v_right|`` of the rectified centroids.
    max_reprojection_error : float  [px]
        Largest reprojection error in either rectified image.
    min_depth, max_depth : float  [m]
        Accepted depth range in the left rectified frame.

    """

    max_epipolar_error: float = 2.0
    max_reprojection_error: float = 1.5
    min_depth: float = 0.2
    max_depth: float = 2.0


@dataclass(frozen=True)
class StereoPoint:
    """
    One triangulated marker and its checks.

    Attributes
    ----------
    ok : bool
        Whether every limit holds.
    reason : str
        ``ok``, ``epipolar``, ``reprojection`` or ``depth`` (the first failed limit).
    p_base : (3,) ndarray  [m]
        The point in ``cbha_base``.
    p_rect : (3,) ndarray  [m]
        The point in the left rectified frame.
    epipolar_error : float  [px]
        ``|v_left - v_right|``.
    reprojection_error : float  [px]
        Larger reprojection error of the two images.

    """

    ok: bool
    reason: str
    p_base: np.ndarray
    p_rect: np.ndarray
    epipolar_error: float
    reprojection_error: float


def rectify_pixels(camera, pixels):
    """
    Map raw pixel coordinates to the rectified image of a camera.

    Parameters
    ----------
    camera : CameraModel
        The camera (K, D, R, P).
    pixels : (N, 2) array_like  [px]
        Raw (distorted) pixel coordinates.

    Returns
    -------
    (N, 2) ndarray  [px]
        Rectified pixel coordinates.

    """
    points = np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
    rectified = cv2.undistortPoints(points, camera.camera_matrix, camera.distortion,
                                    R=camera.rectification, P=camera.projection,
                                    criteria=UNDISTORT_CRITERIA)
    return rectified.reshape(-1, 2)


def normalized_rays(camera, pixels):
    """
    Map raw pixel coordinates to normalized ray directions of the raw camera frame.

    Parameters
    ----------
    camera : CameraModel
        The camera (K, D).
    pixels : (N, 2) array_like  [px]
        Raw (distorted) pixel coordinates.

    Returns
    -------
    (N, 2) ndarray
        ``(x / z, y / z)`` of the rays in the raw optical frame.

    """
    points = np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
    return cv2.undistortPoints(points, camera.camera_matrix, camera.distortion,
                               criteria=UNDISTORT_CRITERIA).reshape(-1, 2)


def project_raw(camera, p_camera):
    """
    Project points of a camera's raw optical frame into its raw (distorted) image.

    Parameters
    ----------
    camera : CameraModel
        The camera (K, D).
    p_camera : (N, 3) array_like  [m]
        Points in the raw optical frame (z > 0).

    Returns
    -------
    (N, 2) ndarray  [px]
        Raw pixel coordinates.

    """
    points = np.asarray(p_camera, dtype=np.float64).reshape(-1, 1, 3)
    pixels, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), camera.camera_matrix,
                                  camera.distortion)
    return pixels.reshape(-1, 2)


def triangulate(rig, left_pixel, right_pixel, limits=StereoLimits()):
    """
    Triangulate one marker from its raw centroids in both images.

    Parameters
    ----------
    rig : StereoRig
        The calibrated rig.
    left_pixel, right_pixel : (2,) array_like  [px]
        Raw centroids in the left and right images.
    limits : StereoLimits
        Rejection limits.

    Returns
    -------
    StereoPoint
        The point with its errors; ``ok`` False (and ``reason``) if a limit fails.

    """
    rect_left = rectify_pixels(rig.left, left_pixel)[0]
    rect_right = rectify_pixels(rig.right, right_pixel)[0]
    homogeneous = cv2.triangulatePoints(rig.left.projection, rig.right.projection,
                                        rect_left.reshape(2, 1), rect_right.reshape(2, 1))
    w = float(homogeneous[3, 0])
    # (x, y, z, 1) of the point in the left rectified frame (w / w is exactly 1)
    p_rect_h = homogeneous[:, 0] / w if w != 0.0 else np.array([np.inf, np.inf, np.inf, 1.0])
    p_rect = p_rect_h[:3]
    epipolar = abs(float(rect_left[1] - rect_right[1]))
    reprojection = max(_reprojection_error(rig.left.projection, p_rect_h, rect_left.tolist()),
                       _reprojection_error(rig.right.projection, p_rect_h, rect_right.tolist()))
    p_left = rig.left.rectification.T @ p_rect
    p_base = rig.base_from_left_points(p_left)[0]
    depth = float(p_rect[2])
    if not (np.isfinite(p_base).all() and epipolar <= limits.max_epipolar_error):
        reason = 'epipolar'
    elif not reprojection <= limits.max_reprojection_error:
        reason = 'reprojection'
    elif not limits.min_depth <= depth <= limits.max_depth:
        reason = 'depth'
    else:
        reason = 'ok'
    return StereoPoint(reason == 'ok', reason, p_base, p_rect, epipolar, reprojection)


def _reprojection_error(projection, p_rect_h, pixel):
    """Distance [px] between ``pixel`` and the projection of ``(x, y, z, 1)`` by ``projection``."""
    u, v, scale = (projection @ p_rect_h).tolist()
    if not scale > 0.0:
        return np.inf
    return float(np.hypot(u / scale - pixel[0], v / scale - pixel[1]))
