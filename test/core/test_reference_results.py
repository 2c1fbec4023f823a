"""
The core's results equal those recorded before its kernels were reorganised by equation.

``test/reference_cases.py`` runs the control tick (every shipped scene, every branch of the
solver's options, the general actuator paths), the static solve, the shape estimator and one
identification; ``test/data/reference_results.npz`` holds their results as the code of commit
72c4a64 gave them. A tick is a fixed sequence of arithmetic: it agrees to 1e-9 of each array's
largest entry, but where proxsuite solves the QP: its iterate is converged to a residual of
1e-10 of the normalised QP, whose smallest curvature is the proximal weight (1e-4), so its
actuation agrees to 1e-6. The static solve, the estimator and the identification iterate to a
tolerance: they agree within it.
"""

import numpy as np
import pytest
from reference_cases import (estimator_case, identification_case, REFERENCE, static_cases,
                             tick_cases)

TICK_TOLERANCE = 1e-9
"""Relative to the largest entry of each array."""
ACTUATION_TOLERANCE = 1e-8
"""The same for a tick's actuation (see the module docstring)."""
PROXSUITE_TOLERANCE = 1e-6
"""The same for ticks whose QP proxsuite solves (see the module docstring)."""


@pytest.fixture(scope='module')
def reference():
    with np.load(REFERENCE) as data:
        return {key: data[key] for key in data.files}


def _close(got, expected, tolerance, name):
    expected = np.asarray(expected)
    if expected.dtype.kind in 'US':
        np.testing.assert_array_equal(got, expected, err_msg=name)
        return
    scale = max(float(np.nanmax(np.abs(expected))), 1e-300) if expected.size else 1.0
    np.testing.assert_allclose(got, expected, rtol=0, atol=tolerance * scale, err_msg=name,
                               equal_nan=True)


def _compare(case, results, reference, tolerances, default=TICK_TOLERANCE):
    keys = sorted(key.split('/', 1)[1] for key in reference if key.startswith(case + '/'))
    assert keys == sorted(results), f'{case}: recorded {keys}, got {sorted(results)}'
    for name in keys:
        _close(results[name], reference[f'{case}/{name}'], tolerances.get(name, default),
               f'{case}/{name}')


def test_ticks_equal_the_recorded_ticks(reference, tmp_path):
    cases = 0
    for case, results in tick_cases(tmp_path):
        proxsuite = case.endswith('proxsuite')
        _compare(case, results, reference,
                 {'actuation': PROXSUITE_TOLERANCE if proxsuite else ACTUATION_TOLERANCE},
                 PROXSUITE_TOLERANCE if proxsuite else TICK_TOLERANCE)
        cases += 1
    assert cases == 14


def test_static_solves_equal_the_recorded_ones(reference):
    # Newton to a residual of 1e-10 of the load: the poses agree far below a micrometre; the
    # iteration counts may differ by the last iteration
    for case, results in static_cases():
        iterations = results.pop('iterations')
        recorded = reference[f'{case}/iterations']
        assert np.all(np.abs(iterations - recorded) <= 1), case
        reference_case = {key: value for key, value in reference.items()
                          if not key.endswith('/iterations')}
        _compare(case, results, reference_case, {'positions': 1e-9, 'quaternions': 1e-9,
                                                 'residual_norm': 1.0})


def test_the_estimator_equals_the_recorded_updates(reference):
    _compare('estimator', estimator_case(), reference, {})


def test_the_identification_equals_the_recorded_fit(reference):
    # a Gauss-Newton fit to its own tolerance
    _compare('identification', identification_case(), reference,
             {'values': 1e-6, 'standard_errors': 1e-4, 'rms_after': 1e-4})
