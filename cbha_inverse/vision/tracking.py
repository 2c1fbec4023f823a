"""
The stereo tip tracker without ROS: an image pair in, the marker in ``cbha_base`` (or why not) out.

:class:`StereoTracker` keeps one :class:`~cbha_inverse.vision.marker.MarkerTracker` per camera
(window search around the last detection, full frame when lost), triangulates the two centroids
(:func:`~cbha_inverse.vision.stereo.triangulate`) and applies the rejection limits. A rejected
pair resets both windows, so the next pair is searched over the full frames.
"""

from dataclasses import dataclass

from cbha_inverse.vision.marker import MarkerTracker
from cbha_inverse.vision.stereo import StereoLimits, triangulate
import numpy as np

REJECTION_REASONS = ('no_marker_left', 'no_marker_right', 'no_marker_both', 'ambiguous',
                     'epipolar', 'reprojection', 'depth')
"""Every reason :meth:`StereoTracker.track` can give for a rejected pair."""

MISSING_POINT = np.full(3, np.nan)
MISSING_POINT.flags.writeable = False
"""``p_base`` of a rejected pair (read-only: shared by every such result)."""


@dataclass(frozen=True)
class TrackResult:
    """
    Result of one image pair.

    Attributes
    ----------
    ok : bool
        Whether a point passed every check.
    reason : str
        ``ok`` or one of :data:`REJECTION_REASONS`.
    p_base : (3,) ndarray  [m]
        The marker in ``cbha_base`` (NaN when not triangulated).
    epipolar_error, reprojection_error : float  [px]
        Errors of the triangulation (NaN when not triangulated).
    windowed : bool
        Whether both centroids came from the search windows.

    """

    ok: bool
    reason: str
    p_base: np.ndarray
    epipolar_error: float = float('nan')
    reprojection_error: float = float('nan')
    windowed: bool = False


class StereoTracker:
    """
    Track the tip marker in image pairs of a calibrated rig.

    Parameters
    ----------
    rig : StereoRig
        The cameras and ``base_from_left``.
    marker : MarkerParams
        Detection parameters.
    limits : StereoLimits
        Rejection limits.

    """

    def __init__(self, rig, marker, limits=StereoLimits()):
        self.rig = rig
        self.limits = limits
        self.trackers = (MarkerTracker(marker), MarkerTracker(marker))

    def track(self, left, right, order='bgr'):
        """
        Find the marker in one image pair.

        Parameters
        ----------
        left, right : (H, W, 3) or (H, W) ndarray of uint8
            Raw images of the left and right cameras (sizes as in their camera models).
        order : str
            ``bgr``, ``rgb`` or ``mono``.

        Returns
        -------
        TrackResult
            The point in ``cbha_base`` or the reason of the rejection.

        """
        found_left = self.trackers[0].detect(left, order)
        found_right = self.trackers[1].detect(right, order)
        missing = MISSING_POINT
        if not (found_left.found and found_right.found):
            self.reset()
            if 'ambiguous' in (found_left.reason, found_right.reason):
                return TrackResult(False, 'ambiguous', missing)
            side = ('both' if not (found_left.found or found_right.found) else
                    'left' if not found_left.found else 'right')
            return TrackResult(False, f'no_marker_{side}', missing)
        point = triangulate(self.rig, found_left.centroid, found_right.centroid, self.limits)
        windowed = found_left.windowed and found_right.windowed
        if not point.ok:
            self.reset()
            return TrackResult(False, point.reason, missing, point.epipolar_error,
                               point.reprojection_error, windowed)
        return TrackResult(True, 'ok', point.p_base, point.epipolar_error,
                           point.reprojection_error, windowed)

    def reset(self):
        """Forget the last detections (next pair: full-frame search)."""
        for tracker in self.trackers:
            tracker.reset()
