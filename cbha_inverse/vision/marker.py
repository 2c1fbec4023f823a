"""
Marker detection in one image: a red sphere (default, sub-pixel centroid) or an ArUco tag.

Red sphere: pixels inside an HSV range (red wraps around hue 0: two hue bands) form candidate
blobs (external contours); a blob is a candidate if its area and circularity ``4 pi A / P²`` lie
within limits, and its score is ``area * circularity``. Two candidates whose scores differ by less
than ``ambiguity_ratio`` are *ambiguous* and the image gives no marker. The centroid is the
redness-weighted mean (``max(R - max(G, B), 0)``, brightness for mono images) over the blob
grown by two pixels, so anti-aliased edge pixels count by their coverage: sub-pixel.

ArUco (option): ``cv2.aruco`` finds the tag of the configured dictionary and id; the centroid is
the mean of its four corners (refined to sub-pixel). Two tags with that id are ambiguous.

:class:`MarkerTracker` searches a window around its last detection first and the full frame when
the marker is not found there.
"""

from dataclasses import dataclass, replace

import cv2
import numpy as np


@dataclass(frozen=True)
class MarkerParams:
    """
    Detection parameters (the node's ``marker.*`` parameters).

    Attributes
    ----------
    kind : str
        ``sphere`` (red sphere) or ``aruco``.
    hue_max_low : int  [OpenCV hue 0..179]
        Red band 1: hue in ``[0, hue_max_low]``.
    hue_min_high : int
        Red band 2: hue in ``[hue_min_high, 179]``.
    saturation_min, value_min : int  [0..255]
        Least saturation and value of a marker pixel.
    mono_threshold : int  [0..255]
        Mono images: least brightness of a marker pixel (the sphere is the brightest blob).
    min_area, max_area : float  [px²]
        Accepted blob area.
    min_circularity : float  [-]
        Least ``4 pi A / P²`` (1 for a disc).
    ambiguity_ratio : float  [-]
        Second-best score / best score above which the detection is ambiguous.
    window : int  [px]
        Half size of the search window around the last detection (0: always the full frame).
    aruco_dictionary : str
        ``cv2.aruco`` predefined dictionary name, e.g. ``DICT_4X4_50``.
    aruco_id : int
        Tag id of the marker.
    coarse_step : int
        Full-frame search: subsampling step of the first pass (1: none).

    """

    kind: str = 'sphere'
    hue_max_low: int = 10
    hue_min_high: int = 170
    saturation_min: int = 120
    value_min: int = 60
    mono_threshold: int = 200
    min_area: float = 20.0
    max_area: float = 20000.0
    min_circularity: float = 0.75
    ambiguity_ratio: float = 0.3
    window: int = 48
    aruco_dictionary: str = 'DICT_4X4_50'
    aruco_id: int = 0
    coarse_step: int = 2


@dataclass(frozen=True)
class Detection:
    """
    The marker in one image (or why not).

    Attributes
    ----------
    found : bool
        Whether exactly one marker was found.
    reason : str
        ``ok``, ``no_marker`` or ``ambiguous``.
    centroid : (2,) ndarray  [px]
        Raw image coordinates (u right, v down; pixel centres at integers); NaN if not found.
    candidates : int
        Candidate blobs (tags) that passed the shape limits.
    windowed : bool
        Whether the result came from the search window.

    """

    found: bool
    reason: str
    centroid: np.ndarray
    candidates: int
    windowed: bool = False


NOT_FOUND = Detection(False, 'no_marker', np.full(2, np.nan), 0)

GROW_KERNEL = np.ones((5, 5), np.uint8)
GROW_KERNEL.flags.writeable = False
"""Structuring element that grows a blob by two pixels (its edge pixels' partial coverage)."""

CHANNEL_ORDERS = ('bgr', 'rgb', 'mono')
"""Pixel layouts accepted by the detectors: ``(H, W, 3)`` uint8 or ``(H, W)`` uint8."""


def detect_sphere(image, params, order='bgr', offset=(0, 0), skip_border=False):
    """
    Detect the red sphere in an image (or a crop of one).

    Parameters
    ----------
    image : (H, W, 3) or (H, W) ndarray of uint8
        The image (``order`` says which).
    params : MarkerParams
        Limits.
    order : str
        ``bgr``, ``rgb`` or ``mono``.
    offset : (2,) int  [px]
        Position of the crop's top-left pixel in the full image (added to the centroid).
    skip_border : bool
        Ignore blobs that touch the border of ``image`` (a crop cuts them: biased centroid).

    Returns
    -------
    Detection
        The centroid in full-image coordinates, or why there is none.

    """
    candidates = sphere_candidates(image, params, order, skip_border)
    return _decide(candidates, image, params, order, offset)


def detect_sphere_coarse(image, params, order='bgr', step=2):
    """
    Detect the red sphere in a full frame, searching a subsampled copy first.

    The blobs found in the image subsampled by ``step`` (any shape, a quarter of the scaled
    least area: the polygon area of a tiny contour is far below its pixel count) are measured
    again at full resolution in a window around each (the 16 largest), and the best of those
    decides, as in :func:`detect_sphere`. A blob that disappears in the subsampling is a few
    pixels wide: below ``min_area`` for ``step`` 2, or too small against the marker to make
    the image ambiguous.

    Parameters
    ----------
    image : (H, W, 3) or (H, W) ndarray of uint8
        The full image.
    params : MarkerParams
        Limits.
    order : str
        ``bgr``, ``rgb`` or ``mono``.
    step : int
        Subsampling step (1: search the full resolution directly).

    Returns
    -------
    Detection
        The centroid, or why there is none.

    """
    if step <= 1:
        return detect_sphere(image, params, order)
    small = subsample(image, step)
    coarse_params = replace(params, min_area=params.min_area / step ** 2 / 4.0,
                            max_area=params.max_area / step ** 2 * 2.0, min_circularity=0.0)
    rows, cols = image.shape[:2]
    found, seen = [], set()
    for _, contour in sphere_candidates(small, coarse_params, order)[:16]:
        x0, y0, width, height = cv2.boundingRect(contour)
        pad = 3 * step + 4
        left, top = max(x0 * step - pad, 0), max(y0 * step - pad, 0)
        right = min((x0 + width) * step + pad, cols)
        bottom = min((y0 + height) * step + pad, rows)
        for score, fine in sphere_candidates(copy_crop(image, top, bottom, left, right),
                                             params, order):
            fine = fine + np.array([left, top], dtype=fine.dtype)
            key = tuple(cv2.boundingRect(fine))
            if key not in seen:
                seen.add(key)
                found.append((score, fine))
    found.sort(key=lambda item: -item[0])
    return _decide(found, image, params, order, (0, 0))


def subsample(image, step):
    """
    Return every ``step``-th pixel of every ``step``-th row: ``image[::step, ::step]``, copied.

    ``cv2.resize`` with nearest-neighbour interpolation and scale ``1 / step`` picks source pixel
    ``floor(step * i)`` for output pixel ``i``: the same pixels as the slice, gathered ~5x faster
    than numpy's strided copy of a 1280x1024 colour frame.

    Parameters
    ----------
    image : (H, W, 3) or (H, W) ndarray of uint8
        The image.
    step : int
        Subsampling step (>= 1).

    Returns
    -------
    (ceil(H / step), ceil(W / step)[, 3]) ndarray of uint8
        The subsampled copy (C-contiguous).

    """
    rows, cols = image.shape[:2]
    size = (-(-cols // step), -(-rows // step))
    small = cv2.resize(image, None, fx=1.0 / step, fy=1.0 / step,
                       interpolation=cv2.INTER_NEAREST)
    if small.shape[1::-1] != size:
        # odd sizes: OpenCV rounds the output size, the slice rounds it up
        return np.ascontiguousarray(image[::step, ::step])
    return small


def copy_crop(image, top, bottom, left, right):
    """
    Return a contiguous copy of ``image[top:bottom, left:right]``.

    A search window of a frame that is not in the cache: numpy's copy loads all its rows at once,
    where OpenCV's colour conversion of the view, row by row, would wait on each row's memory
    (the conversion of a 97x97 window of a frame not in the cache: 35 instead of 60 us).

    Parameters
    ----------
    image : (H, W, 3) or (H, W) ndarray of uint8
        The full image.
    top, bottom, left, right : int  [px]
        Rows ``top:bottom`` and columns ``left:right``.

    Returns
    -------
    (bottom - top, right - left[, 3]) ndarray of uint8
        The crop (C-contiguous).

    """
    return np.ascontiguousarray(image[top:bottom, left:right])


def marker_mask(image, params, order='bgr'):
    """
    Return the pixels of the marker's colour (or brightness): non-zero inside.

    Colour images: hue ``H <= hue_max_low`` or ``H >= hue_min_high`` (OpenCV's 8-bit HSV, hue
    0..179), ``S >= saturation_min`` and ``V >= value_min``. When ``hue_max_low + hue_min_high``
    is even, the two hue bands are the hues at least ``d = (hue_min_high - hue_max_low) / 2``
    from the hue ``c = (hue_max_low + hue_min_high) / 2``: ``H <= c - d`` or ``H >= c + d``
    (integers), so one ``cv2.inRange`` on ``(|H - c|, S, V)`` gives the same pixels as the two
    bands (half the cost); an odd sum takes the two bands.

    Parameters
    ----------
    image : (H, W, 3) or (H, W) ndarray of uint8
        The image (``order`` says which).
    params : MarkerParams
        Colour (``mono``: brightness) limits.
    order : str
        ``bgr``, ``rgb`` or ``mono``.

    Returns
    -------
    (H, W) ndarray of uint8
        255 (mono: non-zero) on the marker's pixels, 0 elsewhere.

    """
    if order == 'mono':
        return cv2.compare(image, params.mono_threshold, cv2.CMP_GE)
    hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV if order == 'bgr' else cv2.COLOR_RGB2HSV)
    low, high = params.hue_max_low, params.hue_min_high
    saturation, value = params.saturation_min, params.value_min
    if (low + high) % 2 == 0 and 0 <= low + high <= 2 * 255:
        centre, reach = (low + high) // 2, (high - low) // 2
        distance = cv2.absdiff(hsv, (centre, 0, 0, 0), dst=hsv)
        return cv2.inRange(distance, (max(reach, 0), saturation, value), (255, 255, 255))
    return cv2.bitwise_or(cv2.inRange(hsv, (0, saturation, value), (low, 255, 255)),
                          cv2.inRange(hsv, (high, saturation, value), (179, 255, 255)))


def sphere_candidates(image, params, order='bgr', skip_border=False):
    """
    Return the blobs of an image that pass the colour, area and circularity limits.

    Parameters
    ----------
    image : (H, W, 3) or (H, W) ndarray of uint8
        The image (``order`` says which).
    params : MarkerParams
        Limits.
    order : str
        ``bgr``, ``rgb`` or ``mono``.
    skip_border : bool
        Ignore blobs that touch the border of ``image``.

    Returns
    -------
    list of (float, ndarray)
        ``(area * circularity, contour)``, best first (contours in ``image`` pixels).

    """
    mask = marker_mask(image, params, order)
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    candidates = []
    rows, cols = mask.shape
    for contour in contours:
        if skip_border:
            x0, y0, width, height = cv2.boundingRect(contour)
            if x0 == 0 or y0 == 0 or x0 + width == cols or y0 + height == rows:
                continue
        area = cv2.contourArea(contour)
        if not params.min_area <= area <= params.max_area:
            continue
        perimeter = cv2.arcLength(contour, True)
        circularity = 4.0 * np.pi * area / max(perimeter * perimeter, 1e-12)
        if circularity >= params.min_circularity:
            candidates.append((area * circularity, contour))
    candidates.sort(key=lambda item: -item[0])
    return candidates


def _decide(candidates, image, params, order, offset):
    """Apply the ambiguity rule to sorted candidates and measure the winner's centroid."""
    if not candidates:
        return NOT_FOUND
    if len(candidates) > 1 and candidates[1][0] >= params.ambiguity_ratio * candidates[0][0]:
        return Detection(False, 'ambiguous', np.full(2, np.nan), len(candidates))
    centroid = _weighted_centroid(candidates[0][1], image, params, order)
    if centroid is None:
        return NOT_FOUND
    u, v = centroid
    return Detection(True, 'ok', np.array([u + offset[0], v + offset[1]], dtype=float),
                     len(candidates))


def _weighted_centroid(contour, image, params, order):
    """Return the weighted centroid ``(u, v)`` [px] over the blob grown by 2 px, or None."""
    x0, y0, width, height = cv2.boundingRect(contour)
    pad = 3
    rows, cols = image.shape[:2]
    top, left = max(y0 - pad, 0), max(x0 - pad, 0)
    bottom, right = min(y0 + height + pad, rows), min(x0 + width + pad, cols)
    crop = image[top:bottom, left:right]
    # max(R - max(G, B), 0) = max(R, M) - M with M = max(G, B): no uint8 wrap-around;
    # max(I - threshold, 0) by the saturating uint8 subtraction
    if order == 'mono':
        weights = cv2.subtract(crop, params.mono_threshold)
    else:
        red = 2 if order == 'bgr' else 0
        greatest = np.maximum(crop[..., 1], crop[..., 2 - red])
        weights = np.maximum(crop[..., red], greatest)
        weights -= greatest
    blob = np.zeros((bottom - top, right - left), np.uint8)
    cv2.drawContours(blob, (contour,), -1, 255, thickness=cv2.FILLED, offset=(-left, -top))
    blob = cv2.dilate(blob, GROW_KERNEL)
    # integer weights: the moments are exact sums
    moments = cv2.moments(cv2.bitwise_and(weights, blob, dst=weights))
    total = moments['m00']
    if not total > 0.0:
        return None
    return moments['m10'] / total + left, moments['m01'] / total + top


class ArucoDetector:
    """
    Find one ArUco tag (by dictionary and id) and return its centre.

    Parameters
    ----------
    params : MarkerParams
        ``aruco_dictionary`` and ``aruco_id``.

    Raises
    ------
    ValueError
        If the dictionary name is not one of ``cv2.aruco``'s predefined dictionaries.

    """

    def __init__(self, params):
        name = params.aruco_dictionary
        if not name.startswith('DICT_') or not hasattr(cv2.aruco, name):
            raise ValueError(f'unknown ArUco dictionary {name!r} (e.g. DICT_4X4_50)')
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))
        parameters = cv2.aruco.DetectorParameters()
        parameters.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        self._detector = cv2.aruco.ArucoDetector(dictionary, parameters)
        self._tag_id = int(params.aruco_id)

    def detect(self, image, order='bgr', offset=(0, 0)):
        """
        Detect the tag.

        Parameters
        ----------
        image : (H, W, 3) or (H, W) ndarray of uint8
            The image.
        order : str
            ``bgr``, ``rgb`` or ``mono``.
        offset : (2,) int  [px]
            Position of the crop in the full image.

        Returns
        -------
        Detection
            The tag centre (mean of its four corners) or why there is none.

        """
        gray = image if order == 'mono' else cv2.cvtColor(
            image, cv2.COLOR_BGR2GRAY if order == 'bgr' else cv2.COLOR_RGB2GRAY)
        corners, ids, _ = self._detector.detectMarkers(gray)
        if ids is None:
            return NOT_FOUND
        matches = [c for c, tag in zip(corners, ids.reshape(-1)) if tag == self._tag_id]
        if not matches:
            return NOT_FOUND
        if len(matches) > 1:
            return Detection(False, 'ambiguous', np.full(2, np.nan), len(matches))
        centre = matches[0].reshape(4, 2).mean(axis=0).astype(float)
        return Detection(True, 'ok', centre + np.asarray(offset, dtype=float), 1)


class MarkerTracker:
    """
    Detect the marker in successive images of one camera, window first, full frame if lost.

    Parameters
    ----------
    params : MarkerParams
        Detection parameters (``kind`` chooses the detector).

    """

    def __init__(self, params):
        self.params = params
        self._aruco = ArucoDetector(params) if params.kind == 'aruco' else None
        self.last = None

    def _detect(self, image, order, offset=(0, 0), windowed=False):
        if self._aruco is not None:
            found = self._aruco.detect(image, order, offset)
            if windowed and found.found and not _inside_margin(found.centroid, offset, image):
                return NOT_FOUND
            return found
        if windowed:
            return detect_sphere(image, self.params, order, offset, skip_border=True)
        return detect_sphere_coarse(image, self.params, order, self.params.coarse_step)

    def detect(self, image, order='bgr'):
        """
        Detect the marker, searching the window around the last detection first.

        Parameters
        ----------
        image : (H, W, 3) or (H, W) ndarray of uint8
            The full image.
        order : str
            ``bgr``, ``rgb`` or ``mono``.

        Returns
        -------
        Detection
            The marker (``windowed`` tells where it was found).

        """
        half = int(self.params.window)
        if self.last is not None and half > 0:
            rows, cols = image.shape[:2]
            u, v = round(float(self.last[0])), round(float(self.last[1]))
            left, top = max(u - half, 0), max(v - half, 0)
            right, bottom = min(u + half + 1, cols), min(v + half + 1, rows)
            if right - left > 4 and bottom - top > 4:
                crop = copy_crop(image, top, bottom, left, right)
                found = self._detect(crop, order, (left, top), windowed=True)
                if found.found:
                    self.last = found.centroid
                    return Detection(True, 'ok', found.centroid, found.candidates, True)
        found = self._detect(image, order)
        self.last = found.centroid if found.found else None
        return found

    def reset(self):
        """Forget the last detection (the next search covers the full frame)."""
        self.last = None


def _inside_margin(centroid, offset, crop, margin=16):
    """Whether a tag centre lies well inside a crop (a tag cut by the border is not found)."""
    u, v = centroid[0] - offset[0], centroid[1] - offset[1]
    rows, cols = crop.shape[:2]
    return margin <= u < cols - margin and margin <= v < rows - margin
