"""Displacement-commanded tendons: round trip with the tension-commanded chain, stretch, slack."""

from cbha_inverse.core import chain
from cbha_inverse.core.actuation.drives import (
    TendonDrives, tensions_of_lengths, unstretched_lengths)
from cbha_inverse.core.statics import solve_static
from cbha_inverse.scene import load_scene
import numpy as np
import pytest

TENSIONS = np.array([3.0, 0.0, 0.0, 1.5, 0.0, 2.0, 0.0, 0.5])   # N, tendon_6f_8c order


@pytest.fixture(scope='module')
def scene():
    return load_scene('tendon_6f_8c')


def _drives(scene, axial_stiffness):
    rest = scene.forward(np.zeros(scene.actuators.n_actuators))
    _, rest_lengths, _ = scene.cable_lengths(rest.state)
    return TendonDrives(scene.tendon_routes, rest_lengths,
                        np.full(rest_lengths.size, float(axial_stiffness)))


def _displaced(scene, drives, displacements):
    return solve_static(scene.model, gravity=scene.gravity, effectors=scene.effectors,
                        load_function=lambda state: drives.loads(state, displacements),
                        load_tangent=lambda state: drives.load_stiffness(state, displacements),
                        strict=True)


@pytest.mark.parametrize('axial_stiffness', [5e3, 5e5])
def test_the_displacements_of_a_tension_equilibrium_hold_the_same_pose(scene, axial_stiffness):
    """Tensions -> pose -> drive displacements -> the displacement-commanded pose: the same."""
    drives = _drives(scene, axial_stiffness)
    by_tension = scene.forward(TENSIONS, strict=True)
    displacements = drives.displacements(by_tension.state, TENSIONS)
    by_displacement = _displaced(scene, drives, displacements)
    np.testing.assert_allclose(by_displacement.effector_positions,
                               by_tension.effector_positions, atol=1e-9)
    tensions, slack = drives.tensions(by_displacement.state, displacements)
    np.testing.assert_allclose(tensions, TENSIONS, atol=1e-6)
    assert slack.max() < 1e-12


def test_stretch_takes_in_the_elastic_elongation(scene):
    """At one pose a tension λ needs ``L λ / (EA + λ)`` more pull-in than the bare path."""
    state = scene.forward(TENSIONS, strict=True).state
    inextensible = _drives(scene, np.inf).displacements(state, TENSIONS)
    elastic = _drives(scene, 2e3).displacements(state, TENSIONS)
    _, lengths, _ = scene.cable_lengths(state)
    np.testing.assert_allclose(inextensible - elastic, lengths * TENSIONS / (2e3 + TENSIONS),
                               rtol=1e-12)
    np.testing.assert_allclose(unstretched_lengths(lengths, TENSIONS, np.full(8, 2e3))
                               * (1.0 + TENSIONS / 2e3), lengths, rtol=1e-14)


def test_a_cable_let_out_beyond_its_path_is_slack(scene):
    """Displacements past the path length: zero tension, the slack reported, no load."""
    drives = _drives(scene, 5e3)
    rest = scene.forward(np.zeros(8), strict=True).state     # where the rest lengths are
    displacements = np.full(8, 2e-3)
    tensions, slack = drives.tensions(rest, displacements)
    np.testing.assert_array_equal(tensions, 0.0)
    np.testing.assert_allclose(slack, 2e-3, rtol=1e-9)
    np.testing.assert_array_equal(drives.loads(rest, displacements), 0.0)
    assert not drives.load_stiffness(rest, displacements).any()
    path, unstretched = np.array([1.0, 1.0]), np.array([0.999, 1.001])
    tensions, slack = tensions_of_lengths(path, unstretched, np.array([1e3, 1e3]))
    np.testing.assert_allclose(tensions, [1e3 * 0.001 / 0.999, 0.0])
    np.testing.assert_allclose(slack, [0.0, 0.001])


def test_the_load_stiffness_is_the_stretch_part_of_the_loads_derivative(scene):
    """
    Finite differences of the loads: the stretch stiffness plus the routing's own change.

    By the product rule ``-d(-Jᵀ λ(q))/dq`` is ``Jᵀ dλ/dq`` (the stretch stiffness) plus the
    change of the routing at constant tension, measured apart by finite differences.
    """
    tensions = TENSIONS + 0.2        # every cable taut: no kink at zero tension
    drives = _drives(scene, 5e4)
    by_tension = scene.forward(tensions, strict=True)
    displacements = drives.displacements(by_tension.state, tensions)
    state = by_tension.state
    stiffness = drives.load_stiffness(state, displacements)

    def at_constant_tension(state):
        _, _, jacobian = scene.cable_lengths(state)
        return -(jacobian.T @ tensions).reshape(-1, 6)

    def central(load, step):
        return (load(chain.retract(state, step)) - load(chain.retract(state, -step))) / 2.0

    n = scene.model.n_frames - 1
    rng = np.random.default_rng(3)
    for _ in range(3):
        step = rng.normal(scale=[1e-7] * 3 + [1e-6] * 3, size=(n, 6))
        stretch = (central(lambda s: drives.loads(s, displacements), step)
                   - central(at_constant_tension, step))
        predicted = -(stiffness @ step.reshape(-1)).reshape(n, 6)
        assert np.linalg.norm(stretch - predicted) < 1e-4 * np.linalg.norm(predicted)


def test_bad_displacements_are_refused(scene):
    """NaN, a wrong length or a cable pulled in by more than its length: a clear error."""
    drives = _drives(scene, 5e3)
    rest = chain.rest_state(scene.model)
    with pytest.raises(ValueError, match='displacements'):
        drives.tensions(rest, np.full(8, np.nan))
    with pytest.raises(ValueError, match='displacements'):
        drives.tensions(rest, np.zeros(7))
    with pytest.raises(ValueError, match='leave no cable'):
        drives.tensions(rest, np.full(8, -10.0))
    with pytest.raises(ValueError, match='finite axial stiffness'):
        _drives(scene, np.inf).loads(rest, np.zeros(8))
    with pytest.raises(ValueError, match='axial_stiffness'):
        TendonDrives(scene.tendon_routes, np.ones(8), np.zeros(8))


def test_a_scene_solves_its_cables_driven_by_displacement(scene):
    """``Scene.forward_displacements``: the pose of the tensions the displacements stand for."""
    by_tension = scene.forward(TENSIONS, strict=True)
    drives = scene.tendon_drives
    np.testing.assert_array_equal(drives.axial_stiffness, 4000.0)     # the scene's cables
    displacements = drives.displacements(by_tension.state, TENSIONS)
    by_displacement = scene.forward_displacements(displacements, strict=True)
    np.testing.assert_allclose(by_displacement.effector_positions,
                               by_tension.effector_positions, atol=1e-9)
    straight = chain.rest_state(scene.model)
    _, straight_lengths, _ = scene.cable_lengths(straight)
    np.testing.assert_allclose(drives.rest_lengths, straight_lengths)   # zero: as built
    with pytest.raises(ValueError, match='displacements'):
        scene.forward_displacements(np.full(8, np.nan))


def test_the_inverse_commanded_in_displacement_reaches_the_tension_commanded_poses(scene):
    """Open loop on the nominal model: the inverse's tensions, as drive displacements, reach."""
    solver = scene.make_inverse_solver()
    rng = np.random.default_rng(5)
    for _ in range(3):
        fraction = rng.uniform(0.0, 0.5, size=8)
        target = scene.forward(fraction * scene.upper_bounds,
                               strict=True).effector_positions[-1]
        for _ in range(60):
            result = solver.step(target[None])
        by_tension = scene.forward(result.actuation, strict=True)
        displacements = scene.tendon_drives.displacements(by_tension.state, result.actuation)
        by_displacement = scene.forward_displacements(displacements, strict=True)
        assert np.linalg.norm(by_tension.effector_positions[-1] - target) < 0.1e-3
        assert np.linalg.norm(by_displacement.effector_positions[-1] - target) < 0.1e-3
