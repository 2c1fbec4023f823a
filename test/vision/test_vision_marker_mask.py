"""
The marker's colour mask holds exactly the pixels of its HSV limits, for every 8-bit colour.

:func:`~cbha_inverse.vision.marker.marker_mask` tests the two red hue bands as one distance
from a centre hue when the bands allow it; the reference tests the limits as written
(``H <= hue_max_low or H >= hue_min_high``, ``S >= saturation_min``, ``V >= value_min``) with
numpy on OpenCV's HSV of an image holding each of the 2^24 colours once.
"""

from cbha_inverse.vision.marker import marker_mask, MarkerParams
import cv2
import numpy as np
import pytest


@pytest.fixture(scope='module')
def every_colour():
    """Return a (4096, 4096, 3) uint8 image with each 8-bit colour exactly once."""
    code = np.arange(1 << 24, dtype=np.uint32)
    channels = [(code >> shift) & 255 for shift in (16, 8, 0)]
    return np.stack(channels, axis=-1).astype(np.uint8).reshape(4096, 4096, 3)


@pytest.mark.parametrize('bands', [
    (10, 170, 120, 60),     # the defaults: symmetric about hue 90
    (8, 176, 100, 40),      # symmetric about hue 92
    (10, 175, 120, 60),     # odd sum: no centre hue, the two bands
    (0, 179, 0, 0),         # a single hue at each end, no colour limit
    (30, 30, 1, 1),         # overlapping bands: every hue
    (-1, 181, 0, 0),        # empty bands
])
@pytest.mark.parametrize('order', ['bgr', 'rgb'])
def test_mask_is_the_hsv_limits_for_every_colour(every_colour, bands, order):
    """Bit for bit the pixels inside the limits (255) and no other (0)."""
    hue_max_low, hue_min_high, saturation_min, value_min = bands
    params = MarkerParams(hue_max_low=hue_max_low, hue_min_high=hue_min_high,
                          saturation_min=saturation_min, value_min=value_min)
    hsv = cv2.cvtColor(every_colour, cv2.COLOR_BGR2HSV if order == 'bgr' else cv2.COLOR_RGB2HSV)
    hue, saturation, value = (hsv[..., k].astype(int) for k in range(3))
    inside = (((hue <= hue_max_low) | (hue >= hue_min_high)) & (saturation >= saturation_min)
              & (value >= value_min))
    mask = marker_mask(every_colour, params, order)
    assert mask.dtype == np.uint8 and mask.shape == every_colour.shape[:2]
    assert np.array_equal(mask, np.where(inside, 255, 0).astype(np.uint8))


def test_mono_mask_is_the_brightness_threshold():
    """Mono images: non-zero exactly where the brightness reaches ``mono_threshold``."""
    image = np.arange(256, dtype=np.uint8).reshape(16, 16)[:, ::-1]
    mask = marker_mask(image[::2, 1:], MarkerParams(mono_threshold=200), 'mono')
    assert np.array_equal(mask > 0, image[::2, 1:] >= 200)
