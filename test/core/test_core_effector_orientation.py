"""
Effectors with orientation rows (``axis``, ``pose``; ``docs/effectors.md``).

The rotational rows of ``W_ea`` against finite differences of the forward model, their sign
(the linear model's prediction turns the frame toward its target), the targets' door, and the
done-when run: poses the forward model reaches at random pressures, reached again by the open
loop on the nominal model.
"""

from functools import lru_cache

from cbha_inverse.core.actuation.effectors import PointEffectors, TargetRefused
from cbha_inverse.core.inverse.results import InverseOptions
from cbha_inverse.core.inverse.solver import InverseSolver
from cbha_inverse.core.so3 import quat_from_matrix, so3_log
from cbha_inverse.scene import load_scene
import numpy as np
import pytest

REACHED_MM = 0.5
"""Position error of a reached pose [mm]."""
REACHED_DEG = 1.0
"""Orientation error of a reached pose [deg]."""


@lru_cache(maxsize=None)
def _scene(name):
    return load_scene(name)


def _pose_solver(scene, **options):
    """Return a solver of the CBHA with its tip a ``pose`` effector (6 rows on 6 bellows)."""
    effectors = PointEffectors(['tip'], [scene.model.n_links], [[0.0, 0.0, 0.0]],
                               scene.model.n_frames, kinds=['pose'])
    return InverseSolver(scene.model, scene.actuators, effectors, gravity=scene.gravity,
                         options=InverseOptions(**options))


def _random_actuation(scene, rng, margin=0.05):
    """Return pressures drawn within the bounds (``margin`` of each range from either bound)."""
    low, high = scene.lower_bounds, scene.upper_bounds
    return low + (margin + (1.0 - 2.0 * margin) * rng.random(low.size)) * (high - low)


def _at_equilibrium(scene, solver, actuation):
    """Put the solver at the scene's equilibrium under ``actuation``; return the forward result."""
    result = scene.forward(actuation, strict=True, tolerance=1e-12)
    solver.reset(result.state, actuation)
    assert solver.prepare()
    return result


def _angle_deg(a, b):
    return float(np.degrees(np.arccos(np.clip(np.dot(a, b), -1.0, 1.0))))


@pytest.mark.parametrize('kind', ['axis', 'pose'])
def test_rotational_rows_of_w_ea_are_the_forward_models_turn(kind):
    """
    Each rotational row of ``W_ea`` is ``c · dψ/dλ_j``: the turn of the tip frame per pascal.

    Central differences of the forward model (static equilibria at ``λ ± h e_j``): the frame's
    turn ``log(R₊ R₋ᵀ) / 2h`` (world axes) on the row's direction ``c``; an axis row's turn of
    the axis ``a₊ - a₋`` too. A wrong sign of the rows (or of their directions) fails both.
    """
    scene = _scene('cbha_approach')
    solver = (scene.make_inverse_solver() if kind == 'axis' else _pose_solver(scene))
    actuation = _random_actuation(scene, np.random.default_rng(3), margin=0.2)
    result = _at_equilibrium(scene, solver, actuation)
    data = solver._data
    frame = scene.model.n_links
    directions = data.orientation_directions.copy()
    rows = 2 if kind == 'axis' else 3
    assert data.w_ea.shape == (3 + rows, 6)
    np.testing.assert_allclose(directions,
                               solver.effectors.orientation_axes @ result.rotations[frame].T,
                               atol=1e-12)
    step = 200.0        # Pa, of 150 kPa
    turned, positions = [], []
    for j in range(actuation.size):
        ends = []
        for sign in (1.0, -1.0):
            moved = actuation.copy()
            moved[j] += sign * step
            ends.append(scene.forward(moved, initial_state=result.state, strict=True,
                                      tolerance=1e-12))
        turned.append(so3_log(ends[0].rotations[frame] @ ends[1].rotations[frame].T)
                      / (2.0 * step))
        positions.append((ends[0].effector_positions[0] - ends[1].effector_positions[0])
                         / (2.0 * step))
        if kind == 'axis':
            axis_change = (ends[0].rotations[frame][:, 0] - ends[1].rotations[frame][:, 0]) / (
                2.0 * step)
            # the axis a = R x turns by ω × a: the row directions c ⟂ a see c · ω
            axis = result.rotations[frame][:, 0]
            np.testing.assert_allclose(np.cross(turned[-1], axis), axis_change, rtol=1e-5,
                                       atol=1e-12)
    turned, positions = np.array(turned).T, np.array(positions).T
    expected = directions @ turned
    scale = np.abs(expected).max()
    np.testing.assert_allclose(data.w_ea[3:], expected, rtol=0, atol=2e-3 * scale)
    np.testing.assert_allclose(data.w_ea[:3], positions, rtol=0,
                               atol=2e-3 * np.abs(positions).max())
    # the rows are not all tiny: a wrong sign would be seen
    assert scale > 1e-7


@pytest.mark.parametrize('qp_solver', ['active_set', 'proxsuite'])
def test_one_tick_turns_the_axis_toward_its_target_as_predicted(qp_solver):
    """
    One tick from equilibrium toward a tilted axis turns it toward the target, as predicted.

    The linear model's prediction: a wrong sign of ``δ_free`` or of ``J_e``'s rotational rows
    turns it away. The compiled tick and the QP solved in Python take the same free gaps.
    """
    scene = _scene('cbha_approach')
    solver = scene.make_inverse_solver(qp_solver=qp_solver)
    actuation = _random_actuation(scene, np.random.default_rng(5), margin=0.3)
    result = _at_equilibrium(scene, solver, actuation)
    axis = result.rotations[scene.model.n_links][:, 0]
    tilt = np.cross(axis, [0.0, 0.0, 1.0])
    tilt /= np.linalg.norm(tilt)
    target = axis * np.cos(0.02) + np.cross(tilt, axis) * np.sin(0.02)      # 1.1 deg away
    before = _angle_deg(axis, target)
    tick = solver.step(result.effector_positions, directions=target)
    after = _angle_deg(solver.effector_directions()[0], target)
    assert tick.status == 'solved'
    assert after < 0.2 * before
    # the prediction (the rotational gap) is what the step left, to first order
    assert np.degrees(tick.predicted_orientation_error) < 0.2 * before


@lru_cache(maxsize=None)
def _sampled_run(kind, samples, seed, max_ticks=40):
    """
    Reach poses of the forward model at random pressures with the open loop on the nominal model.

    Returns ``(position errors [mm], orientation errors [deg], ticks)`` of each sample, the
    ticks until both errors are within :data:`REACHED_MM` and :data:`REACHED_DEG` (and stay:
    the last 5 ticks are checked too).
    """
    scene = _scene('cbha_approach')
    solver = scene.make_inverse_solver() if kind == 'axis' else _pose_solver(scene)
    frame = scene.model.n_links
    rng = np.random.default_rng(seed)
    position_errors, orientation_errors, ticks = [], [], []
    for _ in range(samples):
        result = scene.forward(_random_actuation(scene, rng, margin=0.0), strict=True)
        position = result.effector_positions
        rotation = result.rotations[frame]
        orientation = ({'directions': rotation[:, 0]} if kind == 'axis'
                       else {'quaternions': quat_from_matrix(rotation)})
        solver.reset()
        reached = None
        for tick in range(max_ticks):
            solver.step(position, **orientation)
            now = solver.state.rotations[frame]
            error_mm = 1e3 * np.linalg.norm(solver.effector_positions() - position)
            error_deg = (_angle_deg(now[:, 0], rotation[:, 0]) if kind == 'axis'
                         else float(np.degrees(np.linalg.norm(so3_log(now @ rotation.T)))))
            if error_mm <= REACHED_MM and error_deg <= REACHED_DEG:
                reached = tick + 1 if reached is None else reached
            else:
                reached = None
            if reached is not None and tick + 1 - reached >= 5:
                break
        position_errors.append(error_mm)
        orientation_errors.append(error_deg)
        ticks.append(reached if reached is not None else max_ticks + 1)
    return np.array(position_errors), np.array(orientation_errors), np.array(ticks)


@pytest.mark.parametrize('kind', ['axis', 'pose'])
def test_random_reachable_poses_are_reached_open_loop(kind):
    """
    Poses of the forward model at random pressures are reached again by the open loop.

    A tip position and approach axis (``axis``; or full orientation, ``pose``) the forward model
    reaches at random pressures within the bounds is reached by the open loop from rest on the
    nominal model within 0.5 mm and 1 degree.
    """
    position_errors, orientation_errors, ticks = _sampled_run(kind, 12, 11)
    assert position_errors.max() <= REACHED_MM
    assert orientation_errors.max() <= REACHED_DEG
    assert ticks.max() <= 40


def test_the_targets_door():
    """Orientation targets: normalised within tolerance, refused otherwise, shapes checked."""
    scene = _scene('cbha_approach')
    solver = scene.make_inverse_solver()
    start = scene.rest_effector_positions
    # until given: the tip's axis at rest, +x
    np.testing.assert_allclose(solver.orientation_targets[0], [[1.0, 0.0, 0.0]], atol=1e-12)
    solver.set_orientation_targets(directions=[2.0, 0.0, 2.0])
    np.testing.assert_allclose(solver.orientation_targets[0], [[0.5 ** 0.5, 0.0, 0.5 ** 0.5]])
    for refused in ([0.0, 0.0, 0.0], [np.nan, 1.0, 0.0], [np.inf, 0.0, 0.0]):
        with pytest.raises(TargetRefused):
            solver.set_orientation_targets(directions=refused)
        tick = solver.step(start, directions=refused)
        assert tick.status == 'rejected' and 'rejected' in tick.warnings[0]
        np.testing.assert_array_equal(tick.actuation, np.zeros(6))
    # the refused ones changed nothing
    np.testing.assert_allclose(solver.orientation_targets[0], [[0.5 ** 0.5, 0.0, 0.5 ** 0.5]])
    for wrong in ([1.0, 0.0], [[1.0, 0.0, 0.0]] * 2):
        with pytest.raises(ValueError, match='shape'):
            solver.step(start, directions=wrong)
    with pytest.raises(ValueError, match='no effector is of kind pose'):
        solver.step(start, quaternions=[0.0, 0.0, 0.0, 1.0])

    pose = _pose_solver(scene)
    turn = np.array([0.0, np.sin(0.1), 0.0, np.cos(0.1)])
    pose.set_orientation_targets(quaternions=turn * 1.0005)
    np.testing.assert_allclose(pose.orientation_targets[1], [turn], atol=1e-12)
    for refused in (turn * 1.01, turn * 0.0, [np.nan, 0.0, 0.0, 1.0]):
        with pytest.raises(TargetRefused, match='tip'):
            pose.set_orientation_targets(quaternions=refused)
    np.testing.assert_allclose(pose.orientation_targets[1], [turn], atol=1e-12)
    with pytest.raises(ValueError, match='no effector is of kind axis'):
        pose.set_orientation_targets(directions=[1.0, 0.0, 0.0])

    # a point-only scene: step(targets) as ever, no orientation target taken
    point = _scene('cbha').make_inverse_solver()
    tick = point.step(_scene('cbha').rest_effector_positions)
    assert tick.status != 'rejected' and tick.effector_positions.shape == (1, 3)
    assert np.isnan(tick.predicted_orientation_error)
    with pytest.raises(ValueError, match='no effector is of kind axis'):
        point.step(start, directions=[1.0, 0.0, 0.0])


def test_effector_rows_weights_and_refusals():
    """Row layout and weights of :class:`PointEffectors`; bad definitions refused."""
    effectors = PointEffectors(['a', 'b', 'c'], [1, 2, 3], np.zeros((3, 3)), 5,
                               kinds=['axis', 'point', 'pose'], axes=[[0, 0, 2], [1, 0, 0],
                                                                      [1, 0, 0]],
                               position_weights=[1.0, [1.0, 2.0, 0.0], 0.5],
                               orientation_weights=[[1.0, 3.0], 1.0, 2.0],
                               orientation_lengths=[0.2, 0.1, 0.05])
    assert effectors.n_rows == 9 + 2 + 3
    np.testing.assert_array_equal(effectors.orientation_effectors, [0, 0, 2, 2, 2])
    np.testing.assert_allclose(effectors.row_weights,
                               [1, 1, 1, 1, 2, 0, 0.5, 0.5, 0.5, 0.2, 0.6, 0.1, 0.1, 0.1])
    # the axis rows: unit vectors orthogonal to the (normalised) axis, and to each other
    v = effectors.orientation_axes[:2]
    np.testing.assert_allclose(v @ v.T, np.eye(2), atol=1e-15)
    np.testing.assert_allclose(v @ [0.0, 0.0, 1.0], 0.0, atol=1e-15)
    np.testing.assert_allclose(effectors.axes[0], [0.0, 0.0, 1.0])
    for bad in ({'kinds': ['spin']}, {'kinds': ['axis'], 'axes': [[0.0, 0.0, 0.0]]},
                {'position_weights': [[1.0, 2.0]]}, {'orientation_lengths': [0.0]},
                {'position_weights': [-1.0]}, {'position_weights': [0.0]}):
        with pytest.raises(ValueError):
            PointEffectors(['a'], [1], [[0.0, 0.0, 0.0]], 5, **bad)
