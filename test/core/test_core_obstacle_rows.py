"""Tests of the obstacle rows of the inverse: their linear model, the QP, the statuses."""

from cbha_inverse.core.chain import ChainState
from cbha_inverse.core.inverse.obstacle_rows import sphere_shares, VIOLATION_TOLERANCE
from cbha_inverse.core.inverse.solver import InverseSolver
from cbha_inverse.core.obstacles import Obstacle
from cbha_inverse.core.so3 import so3_exp
from cbha_inverse.scene import load_scene
import numba
from numba.core.runtime import _nrt_python, rtsys
import numpy as np
import pytest

MARGIN = 0.002
"""The obstacle_margin of these tests [m] (the default)."""


@pytest.fixture(scope='module')
def table_scene():
    """Return the scene of the CBHA above a table (80 mm below its base) beside a post."""
    return load_scene('cbha_table')


def _equilibrium(scene, actuation, start=None):
    """Return the model's equilibrium at ``actuation`` (the forward model)."""
    result = scene.forward(actuation, initial_state=start, strict=True)
    return ChainState(result.positions, result.rotations)


def _min_clearance(scene, solver):
    """Return the smallest clearance of the collision spheres to the scene's obstacles [m]."""
    return scene.collision.clearances(solver.state.positions, scene.obstacles).min()


def test_obstacle_rows_match_finite_differences_of_the_forward_model(table_scene):
    """
    ``G Δλ`` is the clearance change of the forward model, ``G λ + c`` the clearance - margin.

    Fails on a wrong normal sign (G changes sign), a missing ``W_sa`` block (G = 0) or a wrong
    free term.
    """
    actuation = np.array([40e3, 10e3, 60e3, 20e3, 70e3, 5e3])
    state = _equilibrium(table_scene, actuation)
    # a tilted wall close to the arm's spheres: rows with a normal along no axis
    wall = Obstacle('wall', 'plane', [0.0, 0.0, 0.0], so3_exp(np.array([0.3, -0.2, 0.0])))
    centres = table_scene.collision.centres(state.positions)
    height = wall.signed_distance(centres).distance - table_scene.collision.radii
    wall = Obstacle('wall', 'plane', wall.rotation[:, 2] * (height.min() - 0.005),
                    wall.rotation)
    solver = table_scene.make_inverse_solver(obstacle_activation=0.01)
    solver.set_obstacles([wall])
    solver.reset(state, actuation)
    assert solver.prepare()
    rows = solver.obstacle_rows
    assert rows.count >= 2 and set(rows.names) == {'wall'}
    spheres = [list(table_scene.collision.frames).index(frame) for frame in rows.frames]

    def clearance(at):
        positions = _equilibrium(table_scene, at, state).positions
        return table_scene.collision.clearances(positions, [wall])[spheres, 0]

    np.testing.assert_allclose(rows.clearances(actuation), clearance(actuation) - MARGIN,
                               atol=2e-6)
    direction = np.array([1.0, -0.5, 0.3, -1.0, 0.8, 0.2]) * 5e3
    fd = (clearance(actuation + direction) - clearance(actuation - direction)) / 2.0
    predicted = rows.matrix @ direction
    assert np.abs(predicted).min() > 1e-4     # every row moves by a tenth of a millimetre
    np.testing.assert_allclose(predicted, fd, rtol=0.02, atol=2e-6)


def _run(scene, solver, target, ticks=60):
    """Tick toward ``target`` (open loop, the model its own plant); return the run."""
    clearances, results = [], []
    for _ in range(ticks):
        results.append(solver.step(target))
        clearances.append(_min_clearance(scene, solver))
        solver.prepare()
    return np.array(clearances), results


def test_a_target_behind_the_table_keeps_the_margin_the_free_inverse_penetrates(table_scene):
    """The model keeps >= margin - 0.5 mm from the table; without rows it sinks several mm."""
    target = table_scene.rest_effector_positions[0] + [0.0, 0.0, -0.08]
    guarded = table_scene.make_inverse_solver()
    clearances, results = _run(table_scene, guarded, target)
    assert clearances.min() >= MARGIN - 5e-4
    assert results[-1].obstacle_rows >= 1
    assert results[-1].status == 'unreachable'        # the table holds the tip from its target
    assert 'target inside obstacle' in ' '.join(results[-1].warnings)
    free = table_scene.make_inverse_solver()
    free.set_obstacles(())
    free_clearances, free_results = _run(table_scene, free, target)
    assert free_clearances.min() < -0.004
    assert free_results[-1].obstacle_rows == 0


def test_rows_end_when_the_obstacle_is_removed(table_scene):
    """After set_obstacles(()) no row remains: the arm goes through where the table was."""
    target = table_scene.rest_effector_positions[0] + [0.0, 0.0, -0.06]
    solver = table_scene.make_inverse_solver()
    _run(table_scene, solver, target, ticks=20)
    solver.set_obstacles(())
    clearances, results = _run(table_scene, solver, target, ticks=20)
    assert results[-1].obstacle_rows == 0 and solver.obstacle_rows is None
    assert clearances[-1] < -0.004
    np.testing.assert_allclose(results[-1].effector_positions[0], target, atol=1e-5)


def test_without_obstacles_the_tick_is_the_obstacle_free_one(table_scene):
    """A solver whose obstacles were removed ticks as the plain scene's, bit for bit."""
    plain = load_scene('cbha').make_inverse_solver()
    cleared = table_scene.make_inverse_solver()
    cleared.set_obstacles(())
    target = table_scene.rest_effector_positions[0] + [0.0, 0.02, -0.03]
    for _ in range(5):
        a, b = plain.step(target), cleared.step(target)
        assert np.array_equal(a.actuation, b.actuation) and a.status == b.status
        plain.prepare()
        cleared.prepare()


def test_a_pushed_arm_reports_obstacle(table_scene):
    """A table through the arm that a tick's step cannot leave: slack, status 'obstacle'."""
    solver = table_scene.make_inverse_solver(max_step=0.01)
    sunk = Obstacle('sunk', 'plane', [0.0, 0.0, -0.01], np.eye(3))
    solver.set_obstacles([sunk])
    solver.reset(_equilibrium(table_scene, np.zeros(6)))
    result = solver.step(table_scene.rest_effector_positions[0])
    assert result.status == 'obstacle'
    assert result.obstacle_violation > VIOLATION_TOLERANCE
    assert np.all(np.isfinite(result.actuation))


def test_bad_obstacles_are_refused(table_scene):
    """A NaN obstacle, something else than an obstacle, obstacles without spheres: refused."""
    with pytest.raises(ValueError, match='position'):
        Obstacle('nan', 'plane', [0.0, np.nan, 0.0], np.eye(3))
    solver = table_scene.make_inverse_solver()
    with pytest.raises(ValueError, match='Obstacle'):
        solver.set_obstacles([{'name': 'table_scene'}])
    assert [o.name for o in solver.obstacles] == ['table', 'post']
    bare = InverseSolver(table_scene.model, table_scene.actuators, table_scene.effectors,
                         gravity=table_scene.gravity)
    with pytest.raises(ValueError, match='collision'):
        bare.set_obstacles(table_scene.obstacles)


def _twins(scene, state, actuation, obstacles, **options):
    """Return the compiled solver and the proxsuite one, at one state, with the obstacles."""
    solvers = []
    for qp_solver in ('active_set', 'proxsuite'):
        solver = scene.make_inverse_solver(qp_solver=qp_solver, **options)
        solver.set_obstacles(obstacles)
        solver.reset(state, actuation)
        solvers.append(solver)
    return solvers


def test_the_compiled_rows_tick_matches_proxsuite_on_the_rows_qp(table_scene):
    """
    Along a run toward a target under the table, the compiled tick's rows QP is proxsuite's.

    At each state of the run both solvers tick from it (reset there: the same history) and
    solve the same QP (the slack eliminated in the compiled one, ``RowsQP`` in proxsuite): the
    same actuation to proxsuite's accuracy, the same rows, slack and statuses.
    """
    target = table_scene.rest_effector_positions[0] + [0.0, 0.0, -0.08]
    span = table_scene.upper_bounds - table_scene.lower_bounds
    state = _equilibrium(table_scene, np.zeros(6))
    compiled, reference = _twins(table_scene, state, np.zeros(6), table_scene.obstacles)
    run = table_scene.make_inverse_solver()
    run.reset(state, np.zeros(6))
    rows_seen = 0
    for _ in range(30):
        for solver in (compiled, reference):
            solver.reset(run.state, run.actuation)
        a, b = compiled.step(target), reference.step(target)
        np.testing.assert_allclose(a.actuation, b.actuation, rtol=0.0, atol=1e-5 * span.max())
        assert a.obstacle_rows == b.obstacle_rows and a.status == b.status
        if a.obstacle_rows:
            np.testing.assert_allclose(a.obstacle_violation, b.obstacle_violation, atol=1e-8)
            rows_seen += 1
        run.step(target)
        run.prepare()
    assert rows_seen > 10
    assert a.status == 'unreachable'


def test_a_pushed_arm_reads_obstacle_in_both_solvers(table_scene):
    """A row that cannot hold: the compiled tick's slack is proxsuite's."""
    sunk = Obstacle('sunk', 'plane', [0.0, 0.0, -0.01], np.eye(3))
    state = _equilibrium(table_scene, np.zeros(6))
    compiled, reference = _twins(table_scene, state, np.zeros(6), [sunk], max_step=0.01)
    target = table_scene.rest_effector_positions[0]
    a, b = compiled.step(target), reference.step(target)
    assert a.status == b.status == 'obstacle'
    assert a.obstacle_violation > VIOLATION_TOLERANCE
    np.testing.assert_allclose(a.obstacle_violation, b.obstacle_violation, rtol=1e-6)
    np.testing.assert_allclose(a.actuation, b.actuation, rtol=0.0, atol=1.0)


def test_obstacles_replaced_at_run_time_change_the_rows(table_scene):
    """Two, one, three obstacles and none in turn: each tick's rows are those of its obstacles."""
    target = table_scene.rest_effector_positions[0] + [0.0, 0.0, -0.08]
    table, post = table_scene.obstacles
    ball = Obstacle('ball', 'sphere', table_scene.rest_effector_positions[0] + [0.0, 0.0, -0.04],
                    np.eye(3), radius=0.01)
    solver = table_scene.make_inverse_solver()
    reference = table_scene.make_inverse_solver(qp_solver='proxsuite')
    for obstacles in ([table, post], [ball], [post, ball, table], [], [table]):
        solver.set_obstacles(obstacles)
        reference.set_obstacles(obstacles)
        for _ in range(10):
            solver.step(target)
            solver.prepare()
        # one tick of both from the run's state (reset there: the same history)
        reference.reset(solver.state, solver.actuation)
        solver.reset(solver.state, solver.actuation)
        a, b = solver.step(target), reference.step(target)
        names = {o.name for o in obstacles}
        rows = solver.obstacle_rows
        assert (rows is None) == (not obstacles)
        if rows is not None:
            assert set(rows.names) <= names and rows.count == len(rows.names)
        assert a.obstacle_rows == b.obstacle_rows
        np.testing.assert_allclose(a.actuation, b.actuation, rtol=0.0, atol=1.0)
        assert (a.obstacle_rows > 0) == bool(names & {'ball', 'table'})


def test_a_long_step_adds_the_rows_of_the_spheres_it_carries_into_an_obstacle(
        table_scene, monkeypatch):
    """
    A table beyond the activation distance, a target far under it: one tick keeps the margin.

    Without the check of the step (one solve per tick) the tick's step sinks the tip's sphere
    into the table, which had no row at the linearisation.
    """
    state = _equilibrium(table_scene, np.zeros(6))
    positions = state.positions
    radii = table_scene.collision.radii
    lowest = (positions[table_scene.collision.frames, 2] - radii).min()
    table = Obstacle('table', 'plane', [0.0, 0.0, lowest - 0.008], np.eye(3))
    target = table_scene.rest_effector_positions[0] + [0.0, 0.0, -0.1]
    clearance = {}
    for rounds in (4, 1):
        monkeypatch.setattr('cbha_inverse.core.inverse.solver.ENTERING_ROUNDS', rounds)
        solver = table_scene.make_inverse_solver(obstacle_activation=0.001)
        solver.set_obstacles([table])
        solver.reset(state, np.zeros(6))
        solver.step(target)
        clearance[rounds] = table_scene.collision.clearances(solver.state.positions,
                                                             [table]).min()
    assert clearance[4] > MARGIN - 1e-3
    assert clearance[1] < MARGIN - 3e-3


def test_ticks_with_rows_are_one_compiled_call_that_allocates_nothing(table_scene):
    """
    A tick holding a sphere off a ball: its rows and their QP run in the one compiled call.

    numba counts every allocation of its runtime: one wrapper of the targets per tick (the one
    array a tick passes to compiled code), nothing else (the rows' buffers are the record's).
    """
    actuation = 0.3 * (table_scene.upper_bounds - table_scene.lower_bounds)
    state = _equilibrium(table_scene, actuation)
    centre = state.positions[16] + [0.0, 0.0, -(table_scene.collision.radii[-1] + 0.008)]
    ball = Obstacle('ball', 'sphere', centre, np.eye(3), radius=0.005)
    solver = table_scene.make_inverse_solver(obstacle_activation=0.005)
    solver.set_obstacles([ball])
    solver.reset(state, actuation)
    target = np.array(table_scene.forward(actuation, strict=True).effector_positions)
    for _ in range(20):
        solver.step(target)
    _nrt_python.memsys_enable_stats()
    try:
        before = rtsys.get_allocation_stats()
        results = [solver.step(target) for _ in range(200)]
        after = rtsys.get_allocation_stats()
    finally:
        _nrt_python.memsys_disable_stats()
    assert all(r.obstacle_rows == 1 and r.status in ('solved', 'saturated') for r in results)
    made = after.alloc - before.alloc
    assert after.free - before.free == made
    assert made == (0 if numba.config.DISABLE_JIT else 200)


def test_sphere_shares_grow_along_the_arm_to_the_next_effector():
    """``f / f_e`` of the first effector at or beyond the sphere; all of the last beyond it."""
    shares = sphere_shares([1, 4, 8, 10, 12], [12, 8])
    np.testing.assert_allclose(shares, [[0.0, 1 / 8], [0.0, 0.5], [0.0, 1.0],
                                        [10 / 12, 0.0], [1.0, 0.0]])
    np.testing.assert_allclose(sphere_shares([3, 6], [4]), [[0.75], [1.0]])


def test_plant_offsets_keep_the_plant_spheres_clear(table_scene):
    """
    A plant measured 3 mm below the model at the tip: the model's tip sphere stays 3 mm higher.

    The target lies behind the table; the model's spheres stop at the margin without an
    offset, at the margin plus the tip sphere's share of the offset with it (the tip's sphere
    is the lowest, its share is 1).
    """
    target = table_scene.rest_effector_positions[0] + [0.0, 0.0, -0.08]
    drop = 0.003
    tip = list(table_scene.collision.frames).index(table_scene.effectors.frames[0])
    ends = []
    for offset in (0.0, -drop):
        solver = table_scene.make_inverse_solver()
        solver.set_plant_offsets([[0.0, 0.0, offset]])
        _run(table_scene, solver, target)
        gaps = table_scene.collision.clearances(solver.state.positions, table_scene.obstacles)
        ends.append(gaps[tip, 0])
    np.testing.assert_allclose(ends, [MARGIN, MARGIN + drop], atol=5e-5)


def test_bad_plant_offsets_are_refused(table_scene):
    """Wrong shape or non-finite offsets raise and change nothing."""
    solver = table_scene.make_inverse_solver()
    with pytest.raises(ValueError, match='shape'):
        solver.set_plant_offsets(np.zeros(3))
    with pytest.raises(ValueError, match='finite'):
        solver.set_plant_offsets([[0.0, np.nan, 0.0]])


def test_targets_inside_obstacles_are_named_by_the_compiled_query(table_scene):
    """A target 1 mm inside a box or a ball names it, 1 mm outside does not; NaN is refused."""
    box = Obstacle('box', 'box', [0.2, 0.1, 0.0], np.eye(3), size=[0.02, 0.04, 0.06])
    ball = Obstacle('ball', 'sphere', [0.2, -0.1, 0.0], np.eye(3), radius=0.01)
    solver = table_scene.make_inverse_solver()
    solver.set_obstacles([box, ball])
    rows = solver.obstacle_rows
    inside_box = [[0.2 + 0.009, 0.1, 0.0]]
    outside_box = [[0.2 + 0.011, 0.1, 0.0]]
    inside_ball = [0.2, -0.1, 0.009]
    assert rows.inside(inside_box) == ('box',)
    assert rows.inside(outside_box) == ()
    assert rows.inside([inside_box[0], inside_ball]) == ('box', 'ball')
    assert rows.inside([outside_box[0], [0.2, -0.1, 0.011]]) == ()
    with pytest.raises(ValueError, match='finite'):
        rows.inside([[np.nan, 0.0, 0.0]])
