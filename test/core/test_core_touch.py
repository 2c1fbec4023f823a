"""Tests of touch with a bounded force: the force rows, their validation, the steady state."""

from cbha_inverse.core.chain import ChainState
from cbha_inverse.core.inverse.correction import TargetCorrector
from cbha_inverse.core.inverse.solver import InverseSolver
from cbha_inverse.core.inverse.touch import touched_obstacles
from cbha_inverse.core.statics import solve_static
from cbha_inverse.report.touch import TABLE_NORMAL, touch_run, wall_in_front, WALL_NORMAL
from cbha_inverse.scene import load_scene
import numpy as np
import pytest
from scipy.optimize import brentq

ACTUATION = np.array([40e3, 10e3, 60e3, 20e3, 70e3, 5e3])
"""An actuation of the CBHA that bends its tip off the straight line [Pa]."""
STEP = np.array([0.0, -3e3, 0.0, 0.0, -4e3, -2e3])
"""A change of it that presses the tip 2.4 mm deeper, predicted to first order [Pa]."""


@pytest.fixture(scope='module')
def table_scene():
    """Return the scene of the CBHA above a table (80 mm below its base) beside a post."""
    return load_scene('cbha_table')


def _tip_height(scene, actuation, force, normal, start):
    """Return the tip's height along ``normal`` under a tip force ``force`` along it [m]."""
    result = solve_static(scene.model, np.concatenate((force * normal, np.zeros(3))),
                          gravity=scene.gravity, actuators=scene.actuators,
                          actuation=actuation, initial_state=start, strict=True,
                          check_warnings=False)
    return result.positions[-1] @ normal


def _reaction(scene, actuation, point, normal, radius, start):
    """
    Return the force along ``normal`` at the tip that puts its sphere on the surface [N].

    The model without contact, root-found (the surface's reaction on a rigid surface).
    """
    return brentq(lambda f: _tip_height(scene, actuation, f, normal, start) - radius
                  - point @ normal, 0.0, 20.0, xtol=1e-12)


@pytest.fixture(scope='module')
def pressed(table_scene):
    """Return a solver linearised at the CBHA's equilibrium at ``ACTUATION``, a touch set."""
    forward = table_scene.forward(ACTUATION, strict=True)
    state = ChainState(forward.positions, forward.rotations)
    solver = table_scene.make_inverse_solver()
    solver.reset(state, ACTUATION)
    tip = forward.positions[-1]
    radius = table_scene.collision.radii[-1]
    # a tilted surface 1.5 mm into the tip's sphere, on its lower side
    normal = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
    point = tip - normal * (radius - 0.0015)
    solver.set_touch('tip', point, normal, [0.0, 10.0])
    assert solver.prepare()
    return solver, state, point, normal, radius


def test_the_force_row_is_the_reaction_of_the_model_held_on_the_surface(table_scene, pressed):
    """
    The predicted force is the force that holds the model's tip sphere on the surface.

    At the linearisation and after a step of the actuation; the reference is root-found on the
    static solve with a tip force along the normal.

    Fails on a wrong compliance (``c``), a wrong ``W_ea`` row or free term of the penetration,
    or a wrong sign of the normal in them.
    """
    solver, state, point, normal, radius = pressed
    rows = solver.touch_rows
    for actuation in (ACTUATION, ACTUATION + STEP):
        forces, violation, warnings = rows.outcome(actuation)
        reference = _reaction(table_scene, actuation, point, normal, radius, state)
        assert 0.01 < reference < 5.0
        # first order in the penetration (1.5 mm) and in the step
        assert forces[0] == pytest.approx(reference, rel=0.02)
        assert violation == 0.0 and warnings == ()


def test_a_wrong_normal_sign_misses_the_reaction(table_scene, pressed):
    """Mutation check: the rows with the normal flipped miss the reaction many times over."""
    solver, state, point, normal, radius = pressed
    reference = _reaction(table_scene, ACTUATION, point, normal, radius, state)
    wrong = table_scene.make_inverse_solver()
    wrong.reset(state, ACTUATION)
    wrong.set_touch('tip', point, -normal, [0.0, 10.0])
    assert wrong.prepare()
    forces, _, _ = wrong.touch_rows.outcome(ACTUATION)
    assert abs(forces[0] - reference) > 5.0 * reference


def test_the_force_rows_bound_the_force_between_its_bounds(pressed):
    """The rows [m]: ``G λ + b`` is the penetration above ``c f_min``, below ``c f_max``."""
    solver, _, point, normal, radius = pressed
    rows = solver.touch_rows
    matrix, constant = rows.rows()
    compliance = rows.compliances[0]
    forces, _, _ = rows.outcome(ACTUATION + STEP)
    lower, upper = matrix @ (ACTUATION + STEP) + constant
    assert lower == pytest.approx(compliance * forces[0], rel=1e-9)
    assert upper == pytest.approx(compliance * (10.0 - forces[0]), rel=1e-9)


@pytest.mark.parametrize('point, normal, bounds, message', [
    ([0.2, 0.0, -0.08], [0.0, 0.0, 1.0], [-0.1, 0.4], 'force bounds'),
    ([0.2, 0.0, -0.08], [0.0, 0.0, 1.0], [0.5, 0.4], 'force bounds'),
    ([0.2, 0.0, -0.08], [0.0, 0.0, 1.0], [0.1, np.inf], 'force bounds'),
    ([0.2, 0.0, -0.08], [0.0, 0.0, 1.0], [np.nan, 0.4], 'force bounds'),
    ([0.2, 0.0, -0.08], [0.0, 0.0, 1.0], [0.1, 0.2, 0.3], 'force bounds'),
    ([0.2, 0.0, -0.08], [0.0, 0.0, 2.0], [0.1, 0.4], 'unit vector'),
    ([0.2, 0.0, -0.08], [0.0, 0.0, 0.0], [0.1, 0.4], 'unit vector'),
    ([0.2, 0.0, -0.08], [0.0, np.nan, 1.0], [0.1, 0.4], 'normal must be 3 finite'),
    ([0.2, np.inf, -0.08], [0.0, 0.0, 1.0], [0.1, 0.4], 'point must be 3 finite'),
    ([0.2, -0.08], [0.0, 0.0, 1.0], [0.1, 0.4], 'point must be 3 finite'),
])
def test_a_bad_touch_is_refused_and_changes_nothing(table_scene, point, normal, bounds, message):
    """Invalid point, normal or bounds: a clear ValueError, no contact target set."""
    solver = table_scene.make_inverse_solver()
    with pytest.raises(ValueError, match=message):
        solver.set_touch('tip', point, normal, bounds)
    assert solver.touches == {}


def test_touch_needs_a_known_effector_with_a_collision_sphere(table_scene):
    """Unknown effectors and effectors without a sphere at their point are refused."""
    solver = table_scene.make_inverse_solver()
    for effector in ('elbow', 1, -1, 0.5):
        with pytest.raises(ValueError, match='unknown effector'):
            solver.set_touch(effector, [0.2, 0.0, -0.08], [0.0, 0.0, 1.0], [0.1, 0.2])
    with pytest.raises(ValueError, match='unknown effector'):
        solver.clear_touch('elbow')
    bare = InverseSolver(table_scene.model, table_scene.actuators, table_scene.effectors,
                         table_scene.gravity)                      # no collision spheres
    with pytest.raises(ValueError, match='no collision sphere'):
        bare.set_touch('tip', [0.2, 0.0, -0.08], [0.0, 0.0, 1.0], [0.1, 0.2])
    touch = solver.set_touch(0, [0.2, 0.0, -0.08], [0.0, 0.0, 1.0], [0.1, 0.2])
    assert solver.touches == {0: touch} and touch.frame == table_scene.model.n_links
    assert solver.clear_touch('tip') and not solver.clear_touch('tip')


def test_the_touched_table_is_found_by_its_surface(table_scene):
    """The table passes through the contact point with the normal +z; the post does not."""
    point = np.array([0.2, 0.0, -0.08])
    assert touched_obstacles(table_scene.obstacles, point, TABLE_NORMAL) == ('table',)
    assert touched_obstacles(table_scene.obstacles, point, -TABLE_NORMAL) == ()
    assert touched_obstacles(table_scene.obstacles, point + [0, 0, 0.01], TABLE_NORMAL) == ()


@pytest.mark.parametrize('gain, drift_mm', [(0.0, 20.0), (0.1, 0.1)])
def test_the_plant_presses_a_wall_within_the_bounds(table_scene, gain, drift_mm):
    """
    The plant presses the wall with a force within the bounds.

    On the plant 10 % softer than the model, with penalty contact: at steady state the plant's
    measured normal force on the tip's sphere lies within the bounds. Open loop the softer
    plant sags along the wall; the closed loop on the tangential error holds the tip on its
    tangential target without undoing the pressing.
    """
    plant_scene = load_scene('cbha_table', stiffness_scale=0.9)
    rest = table_scene.rest_effector_positions[0]
    wall = wall_in_front(rest, table_scene.collision.radii[-1], 0.005)
    point = np.array([wall.position[0], rest[1], rest[2]])
    row = touch_run(table_scene, plant_scene, point, WALL_NORMAL, (0.5, 1.5), ticks=60,
                    obstacles=table_scene.obstacles + (wall,), gain=gain)
    assert row['status'] == 'solved', row['warnings']
    assert row['predicted_n'] == pytest.approx(1.0, abs=1e-3)
    assert 0.5 <= row['measured_n'] <= 1.5
    assert row['drift_mm'] < drift_mm
    assert row['settle_n'] < 1e-3


def test_a_surface_out_of_reach_says_so():
    """A contact target 0.4 m below the base: the bounds cannot hold, the tick says why."""
    solver = load_scene('cbha').make_inverse_solver()
    point = np.array([0.2, 0.0, -0.4])
    solver.set_touch('tip', point, TABLE_NORMAL, [0.2, 0.4])
    for _ in range(20):
        result = solver.step(point[None, :])
    assert result.status == 'unreachable'
    assert result.touch_violation > 0.19 and result.touch_forces[0] == 0.0
    assert any('out of reach' in warning for warning in result.warnings)
    solver.clear_touch('tip')
    result = solver.step(point[None, :])
    assert result.touch_forces is None and np.isnan(result.touch_violation)


def test_the_corrector_integrates_the_tangential_error_of_a_touch():
    """With a touch normal the correction grows in the tangent plane only."""
    corrector = TargetCorrector(2, gain=0.5)
    corrector.correction[0] = [0.001, 0.0, 0.002]
    normal = np.array([0.0, 0.6, 0.8])
    corrector.set_touch_normal(0, normal)
    assert corrector.correction[0] @ normal == pytest.approx(0.0, abs=1e-15)
    target = np.zeros((2, 3))
    measured = np.array([[0.002, 0.004, 0.002], [0.0, 0.0, 0.002]])
    before = corrector.correction.copy()
    corrector.update(target, measured)
    error = -measured[0]
    expected = before[0] + 0.5 * (error - normal * (error @ normal))
    np.testing.assert_allclose(corrector.correction[0], expected, atol=1e-15)
    np.testing.assert_allclose(corrector.correction[1], [0.0, 0.0, -0.001], atol=1e-15)
    corrector.set_touch_normal(0, None)
    assert not corrector.touch_normals.any()
    with pytest.raises(ValueError):
        corrector.set_touch_normal(0, [0.0, 0.0, 0.0])
    with pytest.raises(ValueError):
        corrector.set_touch_normal(2, normal)


def test_the_touching_spheres_row_against_its_surface_gives_way_to_the_force_rows(table_scene):
    """The tip's row against the touched wall is left out; every other row stays, in order."""
    rest = table_scene.rest_effector_positions[0]
    wall = wall_in_front(rest, table_scene.collision.radii[-1], 0.005)
    solver = table_scene.make_inverse_solver()
    solver.set_obstacles(table_scene.obstacles + (wall,))
    solver.set_touch('tip', [wall.position[0], rest[1], rest[2]], WALL_NORMAL, [0.5, 1.5])
    assert solver.prepare()
    rows = solver.obstacle_rows
    pairs = list(zip(rows.names, rows.frames.tolist()))
    assert ('wall', table_scene.model.n_links) in pairs
    matrix, constant, count = solver.touch_rows.stacked(rows)
    kept = [i for i, pair in enumerate(pairs) if pair != ('wall', table_scene.model.n_links)]
    assert count == len(kept) == rows.count - 1 and matrix.shape[0] == count + 2
    np.testing.assert_array_equal(matrix[:count], rows.matrix[kept])
    np.testing.assert_array_equal(constant[:count], rows.constant[kept])
    force_matrix, force_constant = solver.touch_rows.rows()
    np.testing.assert_array_equal(matrix[count:], force_matrix)
    np.testing.assert_array_equal(constant[count:], force_constant)


def test_the_force_rows_hold_the_bound_the_tangential_pull_presses_against(table_scene):
    """
    The upper force row binds where the tangential target pulls the tip into the wall.

    A tangential target 50 mm to the side of a wall contact: the arm, held by the wall, would
    press harder to get there; the upper row holds the predicted force at ``f_max``, whichever
    it is.
    """
    rest = table_scene.rest_effector_positions[0]
    wall = wall_in_front(rest, table_scene.collision.radii[-1], 0.005)
    point = np.array([wall.position[0], rest[1] + 0.05, rest[2]])
    results = {}
    for bounds in ((0.5, 1.5), (0.5, 1.2)):
        solver = table_scene.make_inverse_solver()
        solver.set_obstacles(table_scene.obstacles + (wall,))
        solver.set_touch('tip', point, WALL_NORMAL, bounds)
        for _ in range(40):
            result = solver.step(point[None, :])
            solver.prepare()
        results[bounds] = result
        assert result.touch_forces[0] == pytest.approx(bounds[1], abs=1e-4)
        assert result.touch_violation == 0.0
        assert result.status == 'unreachable' and result.predicted_error > 0.005
    # the tighter bound leaves the tip farther from its tangential target
    assert results[(0.5, 1.2)].predicted_error > results[(0.5, 1.5)].predicted_error
