"""
The inverse solver at its edges: a target out of reach, transposed targets, a zero-range cable.

Each is checked through the public API of
:class:`~cbha_inverse.core.inverse.solver.InverseSolver` on the paper's tendon trunks.
"""

from dataclasses import replace

from cbha_inverse.core.actuation.actuators import ActuatorSet
from cbha_inverse.core.actuation.cables import CableGroup
from cbha_inverse.core.inverse.solver import InverseSolver
from cbha_inverse.scene import load_scene
import numpy as np
import pytest


@pytest.fixture(scope='module')
def tendon_scene():
    """Load the paper's 6-frame, 8-tendon trunk."""
    return load_scene('tendon_6f_8c')


def test_huge_target_saturates_and_the_next_target_is_tracked(tendon_scene):
    """1e308 on each axis: finite actuation within bounds; a sane target afterwards is reached."""
    solver = tendon_scene.make_inverse_solver()
    for _ in range(3):
        out = solver.step([[1e308, 1e308, 1e308]])
        assert np.all(np.isfinite(out.actuation))
        assert np.all(out.actuation >= solver.lower_bounds)
        assert np.all(out.actuation <= solver.upper_bounds)
        # from rest the first steps leave equilibrium (the state says so), then beyond reach
        assert out.status in ('unreachable', 'not_converged') and out.warnings
    target = tendon_scene.forward(np.full(8, 2.0)).effector_positions
    # from the clamped extreme the trust region narrowed: the way back takes some 50 ticks
    for _ in range(70):
        out = solver.step(target)
    assert out.status == 'solved'
    assert np.linalg.norm(out.effector_positions - target) < 1e-6


def test_transposed_targets_are_refused():
    """A (3, k) array is not silently reinterpreted as (k, 3)."""
    scene = load_scene('tendon_10f_16c')
    solver = scene.make_inverse_solver()
    targets = scene.rest_effector_positions
    # the rest shape is not the equilibrium under gravity: the first tick says so
    assert solver.step(targets).status in ('solved', 'saturated', 'not_converged')
    with pytest.raises(ValueError, match=r'\(2, 3\)'):
        solver.step(targets.T)
    with pytest.raises(ValueError, match=r'\(2, 3\)'):
        solver.step(targets.reshape(-1))


def test_zero_range_actuator_is_fixed_at_its_bound(tendon_scene):
    """A cable of zero range: the solver starts, names it, keeps it at 0, drives the rest."""
    scene = tendon_scene
    cables = list(scene.actuators.groups[0].cables)
    cables[1] = replace(cables[1], max_tension=0.0)
    actuators = ActuatorSet([CableGroup(cables, scene.model.n_frames)], scene.model.n_frames)
    solver = InverseSolver(scene.model, actuators, scene.effectors, gravity=scene.gravity)
    solver.warm_up()
    assert any('tip_90' in text and 'zero range' in text for text in solver.warnings)
    target = scene.forward(np.array([3.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 2.0])).effector_positions
    for _ in range(30):
        out = solver.step(target)
    assert np.all(np.isfinite(out.actuation)) and out.actuation[1] == 0.0
    assert np.linalg.norm(out.effector_positions - target) < 1e-6
