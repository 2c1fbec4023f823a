"""
The full-frame search through a subsampled copy decides as the direct full-resolution search.

:func:`~cbha_inverse.vision.marker.detect_sphere_coarse` proposes blobs from a copy subsampled by
``cv2.resize`` and measures them again at full resolution; the reference is
:func:`~cbha_inverse.vision.marker.detect_sphere` on the whole frame (numpy slicing for the
subsampling). Synthetic frames (OpenCV drawing, noise) of even and odd sizes cover what the
rendered pairs of ``test_vision_tracking`` do not: frames without a marker, shapes and sizes the
limits reject, mono images.
"""

from cbha_inverse.vision.marker import (
    detect_sphere, detect_sphere_coarse, MarkerParams, subsample)
import cv2
import numpy as np
import pytest

RED = (30, 20, 200)
"""A marker red in BGR (hue ~3 of 180, saturation ~230, value 200)."""


def _frame(shape, rng, noise=4.0):
    """Return a grey, noisy frame of ``shape`` (rows, cols[, 3]) as uint8."""
    frame = np.full(shape, 90.0) + rng.normal(0.0, noise, shape)
    return np.clip(frame, 0, 255).astype(np.uint8)


@pytest.mark.parametrize('shape', [(1024, 1280, 3), (1023, 1281, 3), (511, 640), (37, 41)])
@pytest.mark.parametrize('step', [2, 3, 4])
def test_subsample_picks_the_pixels_of_the_slice(shape, step):
    """subsample(image, step) is image[::step, ::step], contiguous, for any frame size."""
    image = np.random.default_rng(step).integers(0, 256, shape, dtype=np.uint8)
    small = subsample(image, step)
    assert small.flags['C_CONTIGUOUS']
    assert np.array_equal(small, image[::step, ::step])


def _scenes(rng, shape):
    """Yield (what, frame) pairs: found, ambiguous and rejected scenes of one frame size."""
    rows, cols = shape[:2]
    centre = (int(cols * rng.uniform(0.2, 0.8)), int(rows * rng.uniform(0.2, 0.8)))
    far = ((centre[0] + cols // 2) % cols, (centre[1] + rows // 3) % rows)
    frame = _frame(shape, rng)
    yield 'empty', frame
    marker = frame.copy()
    cv2.circle(marker, centre, int(rng.uniform(6, 25)), RED, -1, cv2.LINE_AA)
    yield 'marker', marker
    twins = marker.copy()
    cv2.circle(twins, far, 15, RED, -1, cv2.LINE_AA)
    yield 'two similar discs', twins
    bar = frame.copy()
    cv2.rectangle(bar, (centre[0] - 60, centre[1] - 3), (centre[0] + 60, centre[1] + 3), RED, -1)
    yield 'a red bar (not round)', bar
    speck = frame.copy()
    cv2.circle(speck, centre, 2, RED, -1)
    yield 'a speck below min_area', speck
    pale = frame.copy()
    cv2.circle(pale, centre, 15, (120, 110, 140), -1, cv2.LINE_AA)
    yield 'a pale disc (low saturation)', pale
    edge = frame.copy()
    cv2.circle(edge, (3, rows // 2), 12, RED, -1, cv2.LINE_AA)
    yield 'a disc cut by the frame edge', edge


REJECTED = ('empty', 'a red bar (not round)', 'a speck below min_area',
            'a pale disc (low saturation)')
"""Scenes of :func:`_scenes` that the limits reject (no marker)."""


@pytest.mark.parametrize('shape', [(1024, 1280, 3), (767, 1023, 3), (480, 640, 3)])
def test_coarse_search_finds_and_rejects_what_the_direct_search_does(shape):
    """Same reason, candidate count and centroid (bit for bit) on found and rejected frames."""
    rng = np.random.default_rng(shape[0])
    params = MarkerParams()
    seen = set()
    for _ in range(3):
        for what, frame in _scenes(rng, shape):
            direct = detect_sphere(frame, params)
            for step in (1, 2):
                coarse = detect_sphere_coarse(frame, params, step=step)
                assert (coarse.reason, coarse.candidates) == (direct.reason, direct.candidates), \
                    (what, step)
                assert np.array_equal(coarse.centroid, direct.centroid, equal_nan=True), what
            seen.add(direct.reason)
            if what == 'marker':
                assert direct.found
            elif what in REJECTED:
                assert direct.reason == 'no_marker', what
    assert seen == {'ok', 'ambiguous', 'no_marker'}


def test_coarse_search_on_mono_frames():
    """Mono frames: the bright disc is found, two are ambiguous, none is no marker, as direct."""
    rng = np.random.default_rng(4)
    params = MarkerParams(mono_threshold=200)
    frame = _frame((1024, 1280), rng)
    one = frame.copy()
    cv2.circle(one, (700, 300), 14, 250, -1, cv2.LINE_AA)
    two = one.copy()
    cv2.circle(two, (200, 800), 13, 250, -1, cv2.LINE_AA)
    for image, reason in ((frame, 'no_marker'), (one, 'ok'), (two, 'ambiguous')):
        direct = detect_sphere(image, params, 'mono')
        coarse = detect_sphere_coarse(image, params, 'mono', step=2)
        assert direct.reason == coarse.reason == reason
        assert np.array_equal(coarse.centroid, direct.centroid, equal_nan=True)
    assert np.linalg.norm(detect_sphere(one, params, 'mono').centroid - [700, 300]) < 0.05
