import math

from cbha_inverse.core.input_checks import vector_fault
from cbha_inverse.estimate.checks import check_vector
from cbha_inverse.robot.safety import check_command
import numpy as np
import pytest


@pytest.mark.parametrize('values, key, detail', [
    ([1.0, 2.0], 'wrong_length', '2 values, expected 3'),
    ('abc', 'wrong_length', 'x are not numbers'),
    ([1.0, math.nan, 2.0], 'non_finite', 'non-finite x'),
    ([1.0, -math.inf, 2.0], 'non_finite', 'non-finite x'),
    ([1.0, 4.0, 2.0], 'out_of_range', 'x outside [-3, 3] Pa: [1.0, 4.0, 2.0]'),
    ([1.0, -3.5, 2.0], 'out_of_range', 'x outside [-3, 3] Pa: [1.0, -3.5, 2.0]'),
])
def test_vector_fault_names_the_first_fault(values, key, detail):
    assert vector_fault(values, 3, 'x', -3.0, 3.0, ' Pa') == (None, key, detail)


def test_vector_fault_accepts_the_bounds_themselves():
    array, key, detail = vector_fault([[-3.0], [3.0]], 2, 'x', -3.0, 3.0)
    assert (key, detail) == (None, '')
    np.testing.assert_array_equal(array, [-3.0, 3.0])


@pytest.mark.parametrize('values', [[0.0, 5.0], [0.0, -1.0], [math.nan, 0.0], [0.0], 'no'])
def test_the_valve_and_estimator_checks_agree_on_the_key(values):
    check = check_command(values, 2, 4.0)
    _, reason = check_vector(values, 2, 'pressure', limit=4.0)
    if values == [0.0, -1.0]:
        assert check.reason == 'out_of_range' and reason is None
    else:
        assert reason.split(':')[0] == check.reason
