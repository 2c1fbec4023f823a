"""The simulated plant's error parameters as a scene calibration (cbha_sim's model error)."""

from cbha_inverse.scene.calibration import Calibration
from cbha_inverse.sim.plant_errors import plant_errors
import numpy as np
import pytest


def test_plant_errors_map_the_sim_parameters_by_name():
    valves = ('b', 'a')
    errors = plant_errors(('inner', 'outer'), valves, (0.85, 1.0), (0.9, 1.1))
    assert errors.section_stiffness == {'inner': 0.85}
    assert errors.actuator_gain == {'b': 0.9, 'a': 1.1}
    assert plant_errors(('inner', 'outer'), valves, (2.0,), (1.0,)).section_stiffness == {
        'inner': 2.0, 'outer': 2.0}
    assert plant_errors((), valves, (1.0,), (1.0,)) == Calibration()
    with pytest.raises(ValueError, match='section_stiffness_scale needs 1 or 2'):
        plant_errors(('inner', 'outer'), valves, (1.0, 1.0, 1.0), (1.0,))
    with pytest.raises(ValueError, match='section_stiffness_scale needs'):
        plant_errors((), valves, (0.9,), (1.0,))
    with pytest.raises(ValueError, match='cavity_gain_scale must be finite'):
        plant_errors(('inner',), valves, (1.0,), (0.0, 1.0))
    shifted = plant_errors((), valves, (1.0,), (1.0,), (0.002, -0.001, 0.0))
    assert shifted == Calibration(base_position=(0.002, -0.001, 0.0))
    with pytest.raises(ValueError, match='base_offset must be 3 finite numbers'):
        plant_errors((), valves, (1.0,), (1.0,), (0.0, np.inf, 0.0))
    with pytest.raises(ValueError, match='base_offset must be 3 finite numbers'):
        plant_errors((), valves, (1.0,), (1.0,), (0.0, 0.0))
