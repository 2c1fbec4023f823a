"""
The compiled tick: its entries over the solver's preallocated record, nothing allocated per tick.

The linearisation is checked against the composed public steps (evaluation, block Cholesky,
multi-RHS solve, projection, QP matrices) and its half-solves against dense solves, the one
compiled call of a tick against its entries one by one; the allocations of 1,000 ticks are
counted by numba's runtime statistics (compiled code) and by ``tracemalloc`` (Python and numpy).
"""

import functools
import gc
import math
import tracemalloc

from cbha_inverse.core._kernels import tick as kernels
from cbha_inverse.core._kernels.projection import project_effectors
from cbha_inverse.core._kernels.retraction import retract_frames
from cbha_inverse.core.inverse import solver as solver_module
from cbha_inverse.core.inverse.qp import ActiveSetQP, qp_matrices
from cbha_inverse.core.inverse.results import TickResult
from cbha_inverse.scene import load_scene
import numba
from numba.core.runtime import _nrt_python, rtsys
import numpy as np
from oracles.effectors import effector_jacobian
import pytest
from tick_faults import refuse_cholesky


def _circle(scene, n_ticks, radius=0.003):
    phase = 2.0 * np.pi * np.arange(n_ticks) / 200
    targets = np.repeat(np.asarray(scene.workspace_center, dtype=float)[None], n_ticks, axis=0)
    targets[:, -1, 1] += radius * np.cos(phase)
    targets[:, -1, 2] += radius * np.sin(phase)
    return targets


def _close(got, expected, tolerance=1e-9):
    """Assert ``got`` equals ``expected`` within ``tolerance`` of the largest entry's size."""
    np.testing.assert_allclose(got, expected, rtol=0,
                               atol=tolerance * max(np.abs(expected).max(), 1e-300))


@pytest.mark.parametrize('name', ['tendon_6f_8c', 'tendon_10f_16c', 'cbha'])
def test_the_linearisation_equals_the_composed_steps(name):
    """linearise_tick vs linearise + factor + solve + project_effectors + qp_matrices."""
    scene = load_scene(name)
    solver = scene.make_inverse_solver()
    for target in _circle(scene, 5):
        solver.step(target)
    data, system = solver._data, solver._system
    positions, rotations = data.positions.copy(), data.rotations.copy()
    actuation = data.actuation.copy()
    info, residual_norm = kernels.linearise_tick(data.record)
    assert info == 0 and data.half_solved[0]
    tangent, rhs = system.linearise(positions, rotations, actuation)
    solved = system.factor(tangent).solve(rhs)
    w_ea, w_aa, offset, norm = project_effectors(
        solved, rhs, positions, rotations, data.effector_frames, data.effector_offsets,
        actuation)
    matrices = qp_matrices(w_ea, w_aa, data.scale, energy_weight=solver.options.energy_weight,
                           proximal_weight=solver.options.proximal_weight)
    # the half-solves and the full solves give the same products up to rounding
    _close(data.w_ea, w_ea)
    _close(data.offset, offset, 1e-12)
    _close(data.w_aa, w_aa)
    _close(data.hessian, matrices.hessian)
    _close(data.weighted_w, matrices.weighted_w)
    np.testing.assert_array_equal(data.linearised, actuation)
    assert residual_norm == norm == pytest.approx(np.linalg.norm(rhs[:, 0]), rel=1e-12)
    # the state is only read
    np.testing.assert_array_equal(data.positions, positions)


@pytest.mark.parametrize('name', ['tendon_6f_8c', 'cbha'])
def test_a_failed_cholesky_solves_nothing_and_leaves_the_evaluation(name):
    """
    A tangent that is not positive definite: the tick reports NOT_FACTORED and solves nothing.

    The links' stiffness negated (the first pivot fails: the block Cholesky returns 1): no QP,
    no step, the actuation and the frames as they were, a NaN residual norm, no half-solves;
    the evaluation's ``[r, J_aᵀ]`` is left for the fallback chain, that of the exact
    evaluation at the state.
    """
    scene = load_scene(name)
    solver = scene.make_inverse_solver()
    targets = _circle(scene, 4)
    for target in targets[:3]:
        solver.step(target)
    data, system = solver._data, solver._system
    positions, rotations = data.positions.copy(), data.rotations.copy()
    actuation = data.actuation.copy()
    stiffness = system.stiffness
    writeable = stiffness.flags.writeable
    stiffness.flags.writeable = True
    saved = stiffness.copy()
    try:
        stiffness *= -1.0        # negative definite: the first pivot fails
        code, iterations, _, _, binding, residual_norm = solver._control_tick(
            targets[3], data.record, False, True, True, True)
        assert code == kernels.NOT_FACTORED and iterations == 0 and not binding
        assert math.isnan(residual_norm) and not data.half_solved[0]
        np.testing.assert_array_equal(data.actuation, actuation)
        np.testing.assert_array_equal(data.positions, positions)
        np.testing.assert_array_equal(data.rotations, rotations)
        got_rhs = system.rhs.copy()
        np.testing.assert_array_equal(got_rhs, system.evaluate(positions, rotations, actuation))
        info, residual_norm = kernels.linearise_tick(data.record)
        assert info == 1 and math.isnan(residual_norm)
    finally:
        stiffness[:] = saved
        stiffness.flags.writeable = writeable


@pytest.mark.parametrize('name', ['tendon_6f_8c', 'tendon_10f_16c', 'cbha'])
def test_the_half_solves_give_the_dense_projection_and_step(name):
    """
    The block factor's half-solves against a dense K⁻¹ (`docs/design.md`, steps 2 and 4).

    ``W_ea = J_e K⁻¹ J_aᵀ``, ``W_aa = J_a K⁻¹ J_aᵀ``, the free effector positions
    ``p_e + J_e K⁻¹ r`` and the Newton step ``K⁻¹ (r + J_aᵀ Δλ)`` applied to the frames, from
    the dense tangent and the effectors' dense Jacobian (test/oracles); then the same after the
    fallback chain (full solves ``K⁻¹ [r, J_aᵀ]``, no backward sweep).
    """
    scene = load_scene(name)
    solver = scene.make_inverse_solver(relinearize_every=5)
    for target in _circle(scene, 5):
        solver.step(target)
    data, system = solver._data, solver._system
    if solver._pending:
        kernels.apply_pending_step(data.record)
        solver._pending = False
    positions, rotations = data.positions.copy(), data.rotations.copy()
    previous = data.actuation.copy()
    tangent, rhs = system.linearise(positions, rotations, previous)
    lower = system.dense(tangent)
    kmat = lower + np.tril(lower, -1).T
    jac = effector_jacobian(solver.effectors, rotations)
    jat = rhs[:, 1:].copy()
    free = solver.effectors.positions(positions, rotations).reshape(-1) + jac @ np.linalg.solve(
        kmat, rhs[:, 0])
    w_ea = jac @ np.linalg.solve(kmat, jat)
    w_aa = jat.T @ np.linalg.solve(kmat, jat)
    rng = np.random.default_rng(len(name))
    change = 0.02 * rng.uniform(-1.0, 1.0, previous.size) * data.scale
    expected = retract_frames(positions, rotations,
                              np.linalg.solve(kmat, rhs[:, 0] + jat @ change).reshape(-1, 6),
                              solver.options.max_rotation_step)
    for fallback in (False, True):
        if fallback:
            data.half_solved[0] = False
            data.solved[:] = np.linalg.solve(kmat, system.rhs)
            data.entry('project_tick')(data.record)
        else:
            assert kernels.linearise_tick(data.record)[0] == 0
            assert data.half_solved[0]
        _close(data.w_ea, w_ea)
        _close(data.w_aa, w_aa)
        _close(data.offset + data.w_ea @ previous, free, 1e-12)
        data.actuation[:] = previous + change
        moved_positions, moved_rotations = positions.copy(), rotations.copy()
        data.entry('pending_step_into')(data.record, moved_positions, moved_rotations)
        data.actuation[:] = previous
        _close(moved_positions - positions, expected[0] - positions)
        _close(moved_rotations - rotations, expected[1] - rotations)


@pytest.mark.parametrize('name, every', [('tendon_6f_8c', 1), ('cbha', 1), ('cbha', 5),
                                         ('cbha_approach', 1)])
def test_a_thousand_ticks_allocate_nothing_but_their_results(name, every):
    """
    Compiled code: no allocation but numba's wrapper of each array argument; Python: the result.

    numba counts every allocation of its runtime; each array passed from Python gets one
    wrapper (freed on return), the tick's buffers none (one compiled object, built once), so a
    tick that allocates nothing of its own makes exactly as many allocations as it passes
    arrays: the targets to its one compiled call (``control_tick``), whether it linearises (or
    applies a kept linearisation's step) or not (the circle's ticks stay at equilibrium: no
    call stops before its QP). ``tracemalloc`` then sees numpy keep only the
    results' own arrays (actuation, effector positions, saturated flags) and no memory left
    behind by ticks whose results are dropped.
    """
    scene = load_scene(name)
    solver = scene.make_inverse_solver(relinearize_every=every)
    targets = _circle(scene, 1100)
    for target in targets[:100]:
        solver.step(target)
    # no collection inside the window: one there freed two arrays that an earlier test of the
    # same worker had left to the garbage collector (free 4002 against alloc 4000)
    gc.collect()
    gc.disable()
    _nrt_python.memsys_enable_stats()
    try:
        before = rtsys.get_allocation_stats()
        results = [solver.step(target) for target in targets[100:]]
        after = rtsys.get_allocation_stats()
    finally:
        _nrt_python.memsys_disable_stats()
        gc.enable()
    assert all(r.status in ('solved', 'saturated') for r in results)
    made = after.alloc - before.alloc
    assert after.free - before.free == made
    del results
    if numba.config.DISABLE_JIT:
        # the kernels' coverage run: the entries run as Python (no wrappers, and numpy's
        # temporaries that tracemalloc would take minutes to follow)
        assert made == 0
        return
    assert made == 1000

    m, k = len(scene.actuator_names), len(scene.effector_names)
    domain = [tracemalloc.DomainFilter(True, np.lib.tracemalloc_domain)]
    tracemalloc.start()
    try:
        start = tracemalloc.take_snapshot().filter_traces(domain)
        results = [solver.step(target) for target in targets[100:]]
        kept = sum(stat.size_diff for stat in tracemalloc.take_snapshot().filter_traces(
            domain).compare_to(start, 'filename'))
        del results, start
        # after one run the interpreter's free lists are filled: a second leaves nothing
        traced, _ = tracemalloc.get_traced_memory()
        for target in targets[100:]:
            solver.step(target)
        left, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert kept == 1000 * (8 * m + 24 * k + m)
    # below one byte per tick (the interpreter's own caches move by a few hundred bytes)
    assert abs(left - traced) < 1000


def test_a_tick_result_is_immutable():
    """A TickResult (a named tuple) cannot be changed in place; ``_replace`` makes a new one."""
    fields = (np.arange(3.0), np.ones((1, 3)), 'solved', 'solved', 1, np.zeros(3, dtype=bool),
              0.5, 2.0, {'total': 1e-5}, ('note',))
    result = TickResult(*fields)
    assert (result.status, result.qp_iterations, result.warnings) == ('solved', 1, ('note',))
    with pytest.raises(AttributeError):
        result.status = 'rejected'
    changed = result._replace(status='saturated')
    assert (changed.status, result.status) == ('saturated', 'solved')
    assert changed.actuation is result.actuation


def test_targets_of_any_layout_give_the_same_tick():
    """The compiled entries take C-ordered floats unchecked: step converts any other layout."""
    scene = load_scene('tendon_10f_16c')
    solver = scene.make_inverse_solver()
    target = _circle(scene, 1, radius=0.01)[0]
    read_only = target.copy()
    read_only.flags.writeable = False
    layouts = [target, read_only, np.asfortranarray(target), target.astype('>f8'),
               target.tolist(), np.repeat(target, 2, axis=1)[:, ::2]]
    results = []
    for layout in layouts:
        solver.reset()
        results.append(solver.step(layout))
    # from the rest shape (not the equilibrium under gravity) the first tick says so
    assert results[0].status == 'not_converged'
    for result in results[1:]:
        np.testing.assert_array_equal(result.actuation, results[0].actuation)
        np.testing.assert_array_equal(result.effector_positions, results[0].effector_positions)


def _same_result(got, expected):
    """Assert two tick results are identical (bit for bit; timings: the same keys)."""
    for name in ('actuation', 'effector_positions', 'saturated'):
        np.testing.assert_array_equal(getattr(got, name), getattr(expected, name))
    assert (got.status, got.qp_status, got.qp_iterations, got.warnings) == (
        expected.status, expected.qp_status, expected.qp_iterations, expected.warnings)
    for name in ('predicted_error', 'residual_norm'):
        np.testing.assert_array_equal(getattr(got, name), getattr(expected, name))
    assert list(got.timings) == list(expected.timings)


def _two_calls(solver):
    """Send a solver's ticks through the target check and the two compiled calls one by one."""
    solver._one_call = False
    return solver


def _tick_both(one, two, target, prepare):
    """Step both solvers toward one target; assert the same results and states."""
    got, expected = one.step(target), two.step(target)
    _same_result(got, expected)
    np.testing.assert_array_equal(one._positions, two._positions)
    np.testing.assert_array_equal(one._rotations, two._rotations)
    np.testing.assert_array_equal(one.actuation, two.actuation)
    assert (one._age, one._pending, one._linearised) == (two._age, two._pending,
                                                         two._linearised)
    # the result's arrays are its own
    data = one._data
    for array, buffer in ((got.actuation, data.actuation), (got.saturated, data.free),
                          (got.effector_positions, data.effector_positions)):
        assert not np.shares_memory(array, buffer)
    if prepare:
        assert one.prepare() == two.prepare()
    return got


@pytest.mark.parametrize('name', ['tendon_6f_8c', 'cbha'])
@pytest.mark.parametrize('every', [1, 5])
@pytest.mark.parametrize('prepare', [False, True])
def test_one_compiled_call_gives_the_ticks_of_the_calls_one_by_one(name, every, prepare,
                                                                   monkeypatch):
    """
    ``control_tick`` against the target check, ``linearise_tick`` and ``solve_tick`` one by one.

    The same arithmetic, so the same results bit for bit, over solved and saturated ticks, a
    non-finite target (held), a target beyond reach (clamped), block Choleskys refused (the
    fallback chain, :func:`tick_faults.refuse_cholesky`) and no factorization at all (held),
    with and without ``prepare`` between the ticks (the node's order).
    """
    scene = load_scene(name)
    one = scene.make_inverse_solver(relinearize_every=every)
    two = _two_calls(scene.make_inverse_solver(relinearize_every=every))
    assert one._one_call
    targets = list(_circle(scene, 32, radius=0.01))
    targets[4] = np.full_like(targets[4], np.nan)
    targets[7] = targets[7] + 100.0
    statuses = []
    fallbacks = {id(one): [], id(two): []}
    for tick, target in enumerate(targets):
        if tick == 12:
            for solver in (one, two):
                refuse_cholesky(solver, monkeypatch)
                chain = solver._system.fallback_factors

                def counted(*args, chain=chain, calls=fallbacks[id(solver)], **kwargs):
                    calls.append(tick)
                    return chain(*args, **kwargs)

                monkeypatch.setattr(solver._system, 'fallback_factors', counted)
        if tick == 18:
            for solver in (one, two):
                monkeypatch.setattr(solver._system, 'factor', lambda tangent=None: None)
                monkeypatch.setattr(solver._system, 'factor_exact', lambda: None)
        if tick == 26:
            monkeypatch.undo()
        statuses.append(_tick_both(one, two, target, prepare).status)
    assert fallbacks[id(one)] == fallbacks[id(two)]
    # the fallback chain factored the linearisations of ticks 12-17 (each, or every fifth)
    assert set(range(12, 18)) & set(fallbacks[id(one)])
    assert set(fallbacks[id(one)]) <= set(range(12, 26))
    assert statuses[4] == 'rejected'
    assert 'clamped' in one.step(targets[7]).warnings[0]
    assert 'not_positive_definite' in statuses[18:26]
    assert statuses[-1] in ('solved', 'saturated'), statuses


def test_one_compiled_call_hands_an_unconverged_active_set_to_proxsuite(monkeypatch):
    """With no active-set iteration allowed, proxsuite finishes every tick: the same ticks."""
    no_iteration = functools.partial(ActiveSetQP, max_iterations=0)
    monkeypatch.setattr(solver_module, 'ActiveSetQP',
                        lambda m, max_iterations=None, state=None: no_iteration(m, state=state))
    scene = load_scene('cbha')
    one = scene.make_inverse_solver()
    two = _two_calls(scene.make_inverse_solver())
    calls = {id(solver): 0 for solver in (one, two)}
    for solver in (one, two):
        solve = solver._qp.solve

        def counted(*args, solver=solver, solve=solve, **kwargs):
            calls[id(solver)] += 1
            return solve(*args, **kwargs)

        solver._qp.solve = counted
    for target in _circle(scene, 12, radius=0.01):
        _tick_both(one, two, target, False)
    assert calls[id(one)] == calls[id(two)] == 12


def test_equilibrium_gap_is_the_largest_effector_move_of_the_newton_step():
    """``equilibrium_gap_of`` against numpy: column 0 of ``moved``, three rows per effector."""
    rng = np.random.default_rng(3)
    moved = rng.normal(size=(9, 5))
    expected = np.linalg.norm(moved[:, 0].reshape(-1, 3), axis=1).max()
    assert kernels.equilibrium_gap_of(moved) == pytest.approx(expected, rel=1e-15)
    moved[4, 0] = np.nan
    assert kernels.equilibrium_gap_of(moved) == math.inf


@pytest.mark.parametrize('prepare', [False, True])
def test_a_tick_off_equilibrium_stops_before_its_qp_and_solves_after_the_check(prepare):
    """
    From the rest shape (not the equilibrium under gravity) the first call stops before its QP.

    The one-call tick then checks the linearisation (trust region, restoration) and solves in a
    second call: the same tick as the parts one by one; on the equilibrium that follows, one
    call per tick again.
    """
    scene = load_scene('cbha')
    one = scene.make_inverse_solver()
    two = _two_calls(scene.make_inverse_solver())
    codes = []
    entry = one._control_tick

    def recorded(*args):
        out = entry(*args)
        codes.append(out[0])
        return out

    one._control_tick = recorded
    statuses = []
    for target in _circle(scene, 40, radius=0.002):
        codes.clear()
        statuses.append(_tick_both(one, two, target, prepare).status)
        if len(statuses) == 1:
            assert codes[0] == kernels.OFF_EQUILIBRIUM
    assert statuses[0] == 'not_converged'
    assert statuses[-1] == 'solved'
    assert codes == ([kernels.SOLVED, kernels.SOLVED] if prepare else [kernels.SOLVED])
