"""
Marker detection and triangulation on rendered pairs of the default rig, against the true points.

The renderer casts rays through each lens (distortion inverted point by point); the first test
checks it against OpenCV's forward projection, so the accuracy tests do not only check the
renderer against itself.
"""

from cbha_inverse.paths import config_path
from cbha_inverse.vision.marker import detect_sphere, MarkerParams
from cbha_inverse.vision.render import RenderSettings, StereoRenderer
from cbha_inverse.vision.rig import load_rig
from cbha_inverse.vision.stereo import project_raw, rectify_pixels, triangulate
from cbha_inverse.vision.tracking import StereoTracker
import numpy as np
import pytest

# The CBHA's reach in cbha_base [m] (config/scenes/cbha.yaml: the tip swings about +-0.1 m
# around the workspace centre (0.2308, 0, -0.0292) in y-z, and shortens along x when it bends).
REACH_MIN = np.array([0.15, -0.11, -0.14])
REACH_MAX = np.array([0.26, 0.11, 0.08])


@pytest.fixture(scope='module')
def rig():
    """Load the default rig of config/cameras."""
    return load_rig(config_path('cameras', 'rig.yaml'))


@pytest.fixture(scope='module')
def renderer(rig):
    """Build a renderer of the default rig: noise 2 DN, blur 0.7 px, the rig's distortion."""
    return StereoRenderer(rig, RenderSettings(), seed=11)


def test_rendered_centroid_matches_forward_projection(rig, renderer):
    """The detected centre of a small sphere is projectPoints of its centre (< 0.05 px)."""
    small = StereoRenderer(rig, RenderSettings(marker_radius=0.002, noise_std=0.0), seed=1)
    rng = np.random.default_rng(5)
    for p_base in rng.uniform(REACH_MIN, REACH_MAX, (20, 3)):
        left, _ = small.render(p_base)
        found = detect_sphere(left, MarkerParams(min_area=5.0))
        expected = project_raw(rig.left, rig.left_from_base(p_base))[0]
        assert found.found
        assert np.linalg.norm(found.centroid - expected) < 0.05


def test_rectified_pixels_match_the_projection_matrix(rig):
    """rectify_pixels(projectPoints(X)) = P R X: raw -> rectified through K, D, R, P."""
    rng = np.random.default_rng(2)
    p_left = rig.left_from_base(rng.uniform(REACH_MIN, REACH_MAX, (50, 3)))
    raw = project_raw(rig.left, p_left)
    image = (rig.left.projection @ np.column_stack([p_left @ rig.left.rectification.T,
                                                    np.ones(50)]).T).T
    assert np.abs(rectify_pixels(rig.left, raw) - image[:, :2] / image[:, 2:]).max() < 1e-6


def test_500_rendered_points_triangulate_within_0_3_mm_rms(rig, renderer):
    """Noise, blur and lens distortion: RMS <= 0.3 mm, max <= 1 mm over the CBHA's reach."""
    rng = np.random.default_rng(0)
    points = rng.uniform(REACH_MIN, REACH_MAX, (500, 3))
    tracker = StereoTracker(rig, MarkerParams(window=0))
    errors = []
    for p_base in points:
        result = tracker.track(*renderer.render(p_base))
        assert result.ok, result
        assert result.epipolar_error < 0.3 and result.reprojection_error < 0.3
        errors.append(np.linalg.norm(result.p_base - p_base))
    errors = np.array(errors)
    rms = float(np.sqrt(np.mean(errors ** 2)))
    print(f'\n500 rendered pairs: triangulation RMS {rms * 1e3:.4f} mm, '
          f'max {errors.max() * 1e3:.4f} mm')
    assert rms <= 0.3e-3
    assert errors.max() <= 1.0e-3


def _separated(rig, p_base, candidate, margin_px=6.0):
    """Whether a distractor's image stays clear of the marker's image in both cameras."""
    focal = rig.left.camera_matrix[0, 0]
    for points in (rig.left_from_base(np.vstack([p_base, candidate])),):
        for camera, frame in ((rig.left, points), (rig.right, rig.right_from_left(points))):
            pixels = project_raw(camera, frame)
            radius = (1.0 + 1.2) * 1.1 * focal * 0.006 / frame[:, 2].min()
            if np.linalg.norm(pixels[0] - pixels[1]) < radius + margin_px:
                return False
    return True


def test_distractor_blob_is_rejected_or_the_point_is_right(rig, renderer):
    """
    A second red sphere (and the backbone as clutter): never a wrong point, ambiguity counted.

    The distractor's radius is 0.4 to 1.2 times the marker's: a much smaller one is outscored
    (the marker is found), one of similar size makes the image ambiguous.
    """
    rng = np.random.default_rng(1)
    tracker = StereoTracker(rig, MarkerParams(window=0))
    reasons = {}
    errors = []
    pairs = 0
    while pairs < 80:
        p_base = rng.uniform(REACH_MIN, REACH_MAX)
        distractor = rng.uniform(REACH_MIN, REACH_MAX)
        if not _separated(rig, p_base, distractor):
            continue
        pairs += 1
        backbone = np.linspace([0.0, 0.0, 0.0], p_base - [0.01, 0.0, 0.0], 17)
        left, right = renderer.render(p_base, distractors=[distractor], backbone=backbone,
                                      distractor_radii=[rng.uniform(0.4, 1.2) * 0.006])
        result = tracker.track(left, right)
        reasons[result.reason] = reasons.get(result.reason, 0) + 1
        if result.ok:
            errors.append(np.linalg.norm(result.p_base - p_base))
    print(f'\ndistractor pairs: {reasons}, published max error '
          f'{max(errors, default=0.0) * 1e3:.3f} mm')
    assert reasons.get('ambiguous', 0) > 0 and reasons.get('ok', 0) > 0
    assert reasons.get('ok', 0) + reasons.get('ambiguous', 0) == pairs
    assert max(errors, default=0.0) <= 1.0e-3


def test_window_search_follows_a_path_past_a_distractor(rig, renderer):
    """Along a path, the window keeps the marker although a same-size red sphere is in view."""
    tracker = StereoTracker(rig, MarkerParams(window=48))
    centre = np.array([0.2308, 0.0, -0.0292])
    distractor = centre + [0.0, 0.09, 0.06]
    start = centre + [0.0, -0.06, 0.0]
    left, right = renderer.render(start)
    assert tracker.track(left, right).ok
    windowed = 0
    for angle in np.linspace(0.0, np.pi, 40):
        p_base = centre + 0.06 * np.array([0.0, -np.cos(angle), np.sin(angle)])
        result = tracker.track(*renderer.render(p_base, distractors=[distractor]))
        assert result.ok, result
        assert np.linalg.norm(result.p_base - p_base) < 1.0e-3
        windowed += result.windowed
    assert windowed == 40
    lost = StereoTracker(rig, MarkerParams(window=48))
    assert lost.track(*renderer.render(start, distractors=[distractor])).reason == 'ambiguous'


def test_marker_in_one_image_only_and_colour_orders(rig, renderer):
    """A marker seen by one camera gives no point; rgb and bgr orders give the same point."""
    tracker = StereoTracker(rig, MarkerParams(window=0))
    p_base = np.array([0.2, 0.03, -0.05])
    left, right = renderer.render(p_base)
    empty_left, _ = renderer.render(p_base + [5.0, 0.0, 0.0])
    assert tracker.track(empty_left, right).reason == 'no_marker_left'
    assert tracker.track(left, empty_left).reason == 'no_marker_right'
    assert tracker.track(empty_left, empty_left).reason == 'no_marker_both'
    bgr = tracker.track(left, right)
    rgb = tracker.track(left[..., ::-1].copy(), right[..., ::-1].copy(), order='rgb')
    assert bgr.ok and rgb.ok
    assert np.array_equal(bgr.p_base, rgb.p_base)


def test_depth_and_epipolar_limits_reject(rig):
    """Centroids off the epipolar line, or a point beyond the depth range, are rejected."""
    p_left = rig.left_from_base([0.2308, 0.0, -0.0292])
    left = project_raw(rig.left, p_left)[0]
    right = project_raw(rig.right, rig.right_from_left(p_left))[0]
    assert triangulate(rig, left, right).ok
    assert triangulate(rig, left, right + [0.0, 5.0]).reason == 'epipolar'
    far = rig.left_from_base([-3.0, 0.0, -0.0292])
    far_left = project_raw(rig.left, far)[0]
    far_right = project_raw(rig.right, rig.right_from_left(far))[0]
    assert triangulate(rig, far_left, far_right).reason == 'depth'


def test_mono_images_track_a_bright_sphere(rig):
    """mono8: the brightest blob above mono_threshold is the marker (a lit white sphere)."""
    import cv2
    white = StereoRenderer(rig, RenderSettings(marker_bgr=(255, 255, 255)), seed=3)
    tracker = StereoTracker(rig, MarkerParams(window=0, mono_threshold=240))
    p_base = np.array([0.21, -0.04, 0.01])
    left, right = (cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) for image in white.render(p_base))
    result = tracker.track(left, right, order='mono')
    assert result.ok, result
    assert np.linalg.norm(result.p_base - p_base) < 1.0e-3


def test_aruco_tag_centre_window_and_ambiguity():
    """An ArUco tag of the configured id is found at its centre; two of them are ambiguous."""
    import cv2
    from cbha_inverse.vision.marker import MarkerTracker
    params = MarkerParams(kind='aruco', aruco_dictionary='DICT_4X4_50', aruco_id=7, window=60)
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    tag = cv2.aruco.generateImageMarker(dictionary, 7, 60)
    other = cv2.aruco.generateImageMarker(dictionary, 3, 60)
    image = np.full((480, 640), 255, np.uint8)
    image[200:260, 300:360] = tag
    image[50:110, 50:110] = other
    tracker = MarkerTracker(params)
    found = tracker.detect(image, 'mono')
    assert found.found and np.linalg.norm(found.centroid - [329.5, 229.5]) < 0.6, found
    again = tracker.detect(image, 'mono')
    assert again.windowed and np.linalg.norm(again.centroid - found.centroid) < 0.1
    image[350:410, 500:560] = tag
    assert MarkerTracker(params).detect(image, 'mono').reason == 'ambiguous'
    with pytest.raises(ValueError, match='unknown ArUco dictionary'):
        MarkerTracker(MarkerParams(kind='aruco', aruco_dictionary='DICT_NOPE'))


def test_coarse_full_frame_search_equals_the_direct_search(rig, renderer):
    """The subsampled first pass finds the same blob, so the same centroid, as the direct one."""
    from cbha_inverse.vision.marker import detect_sphere_coarse
    rng = np.random.default_rng(12)
    params = MarkerParams()
    small = StereoRenderer(rig, RenderSettings(marker_radius=0.0025), seed=2)
    reasons = []
    for images, radius in ((renderer, 0.006), (small, 0.0025)):
        for p_base in rng.uniform(REACH_MIN, REACH_MAX, (10, 3)):
            left, _ = images.render(p_base, distractors=[p_base + [0.0, 0.05, 0.0]],
                                    distractor_radii=[rng.uniform(0.3, 1.0) * radius])
            direct = detect_sphere(left, params)
            coarse = detect_sphere_coarse(left, params, step=2)
            assert (direct.reason, direct.candidates) == (coarse.reason, coarse.candidates)
            assert np.array_equal(direct.centroid, coarse.centroid, equal_nan=True)
            reasons.append(direct.reason)
    assert 'ok' in reasons and 'ambiguous' in reasons
