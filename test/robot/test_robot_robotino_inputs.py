"""
The Robotino mapping's limits: wrist set-points clipped and finite, every channel read.

:func:`cbha_inverse.robot.robotino.robotino_bar_command` clips the wrist channels into
``[0, 1.5]`` bar and vents a non-finite one;
:func:`~cbha_inverse.robot.robotino.robotino_pressures` refuses a driver reading with fewer
channels than ``valve_names`` need.
"""

import math

from cbha_inverse.robot.robotino import robotino_bar_command, robotino_pressures
import numpy as np
import pytest


def test_wrist_set_points_are_clipped_and_never_non_finite():
    arm = [1e4] * 6
    np.testing.assert_array_equal(robotino_bar_command(arm, wrist_bar=(-0.5, math.nan))[6:],
                                  [0.0, 0.0])
    np.testing.assert_array_equal(robotino_bar_command(arm, wrist_bar=(9.0, math.inf))[6:],
                                  [1.5, 0.0])
    np.testing.assert_array_equal(robotino_bar_command(arm, wrist_bar=(0.25, 1.0))[6:],
                                  [0.25, 1.0])


def test_driver_readings_need_every_named_channel():
    with pytest.raises(ValueError, match='^5 channels read, valve_names need 6$'):
        robotino_pressures([0.1] * 5)
    np.testing.assert_allclose(robotino_pressures([0.1, 0.2, 0.3, 0.4, 0.5, 0.6]),
                               [1e4, 2e4, 3e4, 4e4, 5e4, 6e4])
