"""
The safety gate's limits: inclusive workspace box, and rejections that name the bad input.

The box's corners belong to it (one ulp outside does not), its corners are validated, and every
refusal of :mod:`cbha_inverse.robot.safety` says what was wrong with which value, so that a
one-character change of a comparison or a message fails here.
"""

import math

from cbha_inverse.robot.safety import (
    bounded_command, check_command, check_point, stale_action, StalenessWatch, WorkspaceBox)
import numpy as np
import pytest


def test_workspace_box_is_closed_and_stores_float_corners():
    box = WorkspaceBox([-1, -2, -3], np.array([1, 2, 3]))
    assert box.lower == (-1.0, -2.0, -3.0) and box.upper == (1.0, 2.0, 3.0)
    assert all(type(v) is float for v in box.lower + box.upper)
    assert box.contains(box.lower) and box.contains(box.upper)
    assert not box.contains(np.nextafter(box.lower, -np.inf))
    assert not box.contains(np.nextafter(box.upper, np.inf))
    assert check_point(box.lower, 'f', 'f', box).ok and check_point(box.upper, 'f', 'f', box).ok


@pytest.mark.parametrize('lower, upper, match', [
    ((0.0, 0.0), (1.0, 1.0, 1.0), '^workspace box corners must have 3 components each$'),
    ((0.0, 0.0, 0.0), (1.0, 1.0), '^workspace box corners must have 3 components each$'),
    ((0.0, 0.0, math.nan), (1.0, 1.0, 1.0), '^workspace box corners must be finite$'),
    ((0.0, 0.0, 0.0), (1.0, math.inf, 1.0), '^workspace box corners must be finite$'),
    ((0.0, 1.0, 0.0), (1.0, 1.0, 1.0),
     r'^workspace box lower \[0.0, 1.0, 0.0\] must be below upper \[1.0, 1.0, 1.0\] in'),
])
def test_workspace_box_rejects_bad_corners(lower, upper, match):
    with pytest.raises(ValueError, match=match):
        WorkspaceBox(lower, upper)


def test_rejections_say_what_is_wrong():
    box = WorkspaceBox((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    assert 'nan' in check_point((math.nan, 0.0, 0.0), 'f', 'f', box).detail
    assert "'g'" in check_point((0.5, 0.5, 0.5), 'g', 'f', box).detail
    assert '[2.0, 0.5, 0.5]' in check_point((2.0, 0.5, 0.5), 'f', 'f', box).detail
    assert check_command([1.0], 3, 10.0).detail == '1 values, expected 3'
    assert check_command([1.0, math.nan, 1.0], 3, 10.0).detail == 'non-finite pressure'
    assert check_command([1.0, 11.0, 1.0], 3, 10.0).detail == (
        'pressure outside [0, 10] Pa: [1.0, 11.0, 1.0]')
    with pytest.raises(ValueError, match='^command: 2 values, expected 3$'):
        bounded_command([1.0, 2.0], np.zeros(3), np.ones(3))
    with pytest.raises(ValueError, match='^command: non-finite values$'):
        bounded_command([1.0, math.inf, 2.0], np.zeros(3), np.ones(3))
    with pytest.raises(ValueError, match=r'timeout must be a finite number > 0, got -1\.0'):
        StalenessWatch(-1.0)
    with pytest.raises(ValueError, match=r"action must be one of \('hold', 'vent'\), got 'x'"):
        stale_action(False, False, 'x')
