"""Kernels (Jl⁻¹, log/exp, retraction), block Cholesky, block LU and the solver's fallbacks."""

from cbha_inverse.core._kernels import evaluation
from cbha_inverse.core._kernels.block_band import (block_backward, block_cholesky,
                                                   block_cholesky_forward, block_forward,
                                                   block_solve, first_nonzero_rows)
from cbha_inverse.core._kernels.block_lu import block_lu, block_lu_solve
from cbha_inverse.core._kernels.retraction import retract_frames
from cbha_inverse.core._kernels.so3 import jl_coefficient, rotation_exp, rotation_log
from cbha_inverse.core.chain import ChainModel, ChainState, rest_state, retract
from cbha_inverse.core.links import timoshenko_compliance
from cbha_inverse.core.system import EquilibriumSystem
from cbha_inverse.scene import load_scene
import numpy as np
from oracles.actuation import oracle
from oracles.chain_forces import assemble_tangent, blocks_to_dense, material_tangent
from oracles.so3 import _jl_inv_coefficient, so3_exp, so3_log
import pytest
from tick_faults import refuse_cholesky


def jl_coefficients(theta):
    return np.array([jl_coefficient(t) for t in theta]).T


def exp_rotations(rotvec):
    out = np.empty((len(rotvec), 3, 3))
    for v, rot in zip(rotvec, out):
        rotation_exp(v, rot)
    return out


def _chain(n):
    c = timoshenko_compliance(0.02, 2e7, 0.45, 0.006)
    return ChainModel.from_compliances(np.broadcast_to(c, (n, 6, 6)),
                                       np.tile([0.02, 0, 0], (n, 1)))


def test_jl_coefficients_are_continuous_at_the_switch():
    theta = np.array([0.5 - 1e-12, 0.5])
    c, dc = jl_coefficients(theta)
    assert c[0] == pytest.approx(c[1], rel=1e-11)
    assert dc[0] == pytest.approx(dc[1], rel=1e-8)
    c0, _ = jl_coefficients(np.array([0.0]))
    assert c0[0] == pytest.approx(1.0 / 12.0)


def test_jl_coefficients_match_se3():
    theta = np.concatenate([[0.0, 1e-9], np.linspace(1e-3, 3.1, 200)])
    c, dc = jl_coefficients(theta)
    c_ref, dc_ref = _jl_inv_coefficient(theta)
    np.testing.assert_allclose(c, c_ref, rtol=1e-13)
    np.testing.assert_allclose(dc, dc_ref, rtol=1e-10)


@pytest.mark.parametrize('angle', [0.0, 1e-10, 0.3, 2.0, 2.4, 2.5, 3.0, np.pi - 1e-9])
def test_rotation_log_inverts_exp_up_to_pi(angle):
    rng = np.random.default_rng(11)
    axes = rng.standard_normal((20, 3))
    vectors = axes / np.linalg.norm(axes, axis=1, keepdims=True) * angle
    out = np.empty(3)
    for v, rot in zip(vectors, so3_exp(vectors)):
        theta = rotation_log(rot, out)
        np.testing.assert_allclose(out, v, atol=1e-12)
        np.testing.assert_allclose(out, so3_log(rot), atol=1e-12)
        assert theta == pytest.approx(angle, abs=1e-12)


def _spd_block_band(rng, n_blocks, width):
    """
    Return a random SPD matrix of 6 x 6 blocks with ``width`` blocks below the diagonal.

    ``A = L Lᵀ`` for a random lower-triangular ``L`` of that block bandwidth with a dominant
    positive diagonal: ``L`` is numpy's Cholesky factor of ``A``, and ``A`` is well conditioned.
    """
    size = 6 * n_blocks
    rows, cols = np.indices((size, size)) // 6
    lower = np.tril(np.where(rows - cols <= width, 0.1 * rng.standard_normal((size, size)), 0.0))
    lower[np.diag_indices(size)] = rng.uniform(2.0, 3.0, size)
    return lower @ lower.T


def _block_band(dense, width):
    """Return the block band ``blocks[c, d] = K_(c+d, c)`` of a dense matrix, block by block."""
    n_blocks = dense.shape[0] // 6
    blocks = np.zeros((n_blocks, width + 1, 6, 6))
    for c in range(n_blocks):
        for d in range(min(width + 1, n_blocks - c)):
            blocks[c, d] = dense[6 * (c + d):6 * (c + d + 1), 6 * c:6 * (c + 1)]
    return blocks


def _factor_matrix(factor):
    """Return the dense ``L`` of a block Cholesky factor (its diagonal blocks hold 1 / L_ii)."""
    n_blocks, widths = factor.shape[:2]
    out = np.zeros((6 * n_blocks, 6 * n_blocks))
    for c in range(n_blocks):
        for d in range(min(widths, n_blocks - c)):
            block = factor[c, d]
            if d == 0:
                block = np.tril(block, -1) + np.diag(1.0 / np.diag(block))
            out[6 * (c + d):6 * (c + d + 1), 6 * c:6 * (c + 1)] = block
    return out


def _close(got, expected, tolerance=1e-12):
    """Assert ``got`` equals ``expected`` within ``tolerance`` of the largest entry's size."""
    np.testing.assert_allclose(got, expected, rtol=0, atol=tolerance * np.abs(expected).max())


@pytest.mark.parametrize('n_blocks, width, n_rhs', [
    (1, 1, 3), (2, 1, 5), (7, 1, 1), (16, 1, 7), (2, 2, 5), (3, 2, 4), (10, 2, 9), (5, 3, 2)])
def test_block_cholesky_gives_numpys_factor_and_dense_solves(n_blocks, width, n_rhs):
    """
    block_cholesky gives numpy's Cholesky factor; the sweeps give the dense triangular solves.

    Of a diagonal block only the lower triangle is read and written: its upper triangle (NaN
    here) is left as it was. block_forward solves ``L Y = R``, block_backward ``Lᵀ X = Y`` and
    block_solve both, bit for bit; block bandwidths 1 (a chain), 2 and 3 (cables that skip
    frames), with fewer blocks than the bandwidth too.
    """
    rng = np.random.default_rng(10 * n_blocks + width + n_rhs)
    dense = _spd_block_band(rng, n_blocks, width)
    blocks = _block_band(dense, width)
    above = np.triu_indices(6, 1)
    blocks[:, 0][:, above[0], above[1]] = np.nan
    assert block_cholesky(blocks) == 0
    assert np.isnan(blocks[:, 0][:, above[0], above[1]]).all()
    lower = np.linalg.cholesky(dense)
    _close(_factor_matrix(blocks), lower)
    rhs = rng.standard_normal((6 * n_blocks, n_rhs))
    forward = rhs.copy()
    block_forward(blocks, forward, np.zeros(n_rhs, dtype=np.int64))
    _close(forward, np.linalg.solve(lower, rhs))
    backward = forward.copy()
    block_backward(blocks, backward)
    _close(backward, np.linalg.solve(lower.T, forward))
    _close(backward, np.linalg.solve(dense, rhs), 1e-11)
    solved = rhs.copy()
    block_solve(blocks, solved)
    np.testing.assert_array_equal(solved, backward)


@pytest.mark.parametrize('width', [1, 2])
def test_the_factor_with_its_sweep_equals_the_factor_then_the_sweep(width):
    """
    block_cholesky_forward gives block_cholesky then block_forward, bit for bit.

    Columns zero down to some row (the ``J_aᵀ`` of a later section's actuators; at a block
    boundary or inside a block, or zero throughout): first_nonzero_rows finds that row, the
    sweep starts at its block and gives the bits of the sweep from row 0; the zeros stay zero.
    Both give the dense half-solve ``L⁻¹ R``.
    """
    rng = np.random.default_rng(width)
    n_blocks, zeros = 8, [0, 3, 6, 8, 30, 47, 48]
    dense = _spd_block_band(rng, n_blocks, width)
    blocks = _block_band(dense, width)
    rhs = rng.standard_normal((6 * n_blocks, len(zeros)))
    for col, rows in enumerate(zeros):
        rhs[:rows, col] = 0.0
    starts = np.full(len(zeros), -1, dtype=np.int64)
    first_nonzero_rows(rhs, starts)
    np.testing.assert_array_equal(starts, zeros)
    fused, swept = blocks.copy(), rhs.copy()
    assert block_cholesky_forward(fused, swept, starts) == 0
    factor, expected = blocks.copy(), rhs.copy()
    assert block_cholesky(factor) == 0
    block_forward(factor, expected, starts)
    np.testing.assert_array_equal(fused, factor)
    np.testing.assert_array_equal(swept, expected)
    from_the_top = rhs.copy()
    block_forward(factor, from_the_top, np.zeros(len(zeros), dtype=np.int64))
    np.testing.assert_array_equal(swept, from_the_top)
    _close(swept, np.linalg.solve(np.linalg.cholesky(dense), rhs))
    for col, rows in enumerate(zeros):
        assert not swept[:rows, col].any()


@pytest.mark.parametrize('width, unknown, pivot', [
    (1, 0, -0.5), (1, 20, -0.5), (2, 27, -2.0), (2, 47, np.nan), (1, 33, np.inf),
    (2, 6, -1e-3)])
def test_block_cholesky_reports_the_first_failing_pivot_and_leaves_it(width, unknown, pivot):
    """
    A pivot that is not positive (or not finite) stops the factorisation at ``6 c + j + 1``.

    The pivot of unknown ``p`` is the Schur complement ``A_pp - A_p,:p A_:p,:p⁻¹ A_:p,p``; planted
    at ``pivot`` (the leading minors stay positive definite), block_cholesky and
    block_cholesky_forward return ``p + 1`` and leave it in ``blocks[c, 0, j, j]``.
    """
    rng = np.random.default_rng(unknown)
    dense = _spd_block_band(rng, 8, width)
    p = unknown
    if np.isfinite(pivot):
        schur = dense[p, :p] @ np.linalg.solve(dense[:p, :p], dense[:p, p]) if p else 0.0
        dense[p, p] = schur + pivot
    else:
        dense[p, p] = pivot
    c, j = divmod(p, 6)
    for fused in (False, True):
        blocks = _block_band(dense, width)
        if fused:
            info = block_cholesky_forward(blocks, rng.standard_normal((48, 3)),
                                          np.zeros(3, dtype=np.int64))
        else:
            info = block_cholesky(blocks)
        assert info == 6 * c + j + 1
        if np.isfinite(pivot):
            assert blocks[c, 0, j, j] == pytest.approx(pivot, rel=1e-9)
        else:
            np.testing.assert_array_equal(blocks[c, 0, j, j], pivot)


def _exact_storage(dense, width):
    """Return the blocks ``blocks[c, B + d] = K_(c+d, c)``, ``d = -B ... B``, of a dense matrix."""
    n_blocks = dense.shape[0] // 6
    blocks = np.zeros((n_blocks, 2 * width + 1, 6, 6))
    for c in range(n_blocks):
        for d in range(max(-width, -c), min(width, n_blocks - 1 - c) + 1):
            blocks[c, width + d] = dense[6 * (c + d):6 * (c + d + 1), 6 * c:6 * (c + 1)]
    return blocks


def _block_banded(rng, n_blocks, width):
    """
    Return a random non-symmetric matrix of 6 x 6 blocks, ``width`` blocks on either side.

    Each diagonal block is a random block of singular values 1 ... 3 (its elimination needs row
    interchanges), the couplings are small against it: elimination without interchanges across
    blocks is stable, as for the tangent near a stable equilibrium.
    """
    size = 6 * n_blocks
    rows, cols = np.indices((size, size)) // 6
    dense = np.where(np.abs(rows - cols) <= width, 0.02 * rng.standard_normal((size, size)), 0.0)
    for c in range(n_blocks):
        left, _ = np.linalg.qr(rng.standard_normal((6, 6)))
        right, _ = np.linalg.qr(rng.standard_normal((6, 6)))
        dense[6 * c:6 * c + 6, 6 * c:6 * c + 6] = (left * rng.uniform(1.0, 3.0, 6)) @ right
    return dense


@pytest.mark.parametrize('n_blocks, width, n_rhs', [
    (1, 1, 2), (2, 1, 3), (9, 1, 5), (2, 2, 3), (3, 2, 1), (10, 2, 8)])
def test_block_lu_solves_random_block_banded_matrices(n_blocks, width, n_rhs):
    """block_lu and block_lu_solve against numpy.linalg.solve (B = 1 and 2, any block count)."""
    rng = np.random.default_rng(10 * n_blocks + width)
    dense = _block_banded(rng, n_blocks, width)
    dense[0, 0] = 0.0       # the first column needs an interchange
    assert np.abs(dense - dense.T).max() > 0.1
    blocks = _exact_storage(dense, width)
    pivots = np.full((n_blocks, 6), -1, dtype=np.int64)
    assert block_lu(blocks, pivots) == 0
    assert np.all((pivots >= np.arange(6)) & (pivots < 6)) and pivots[0, 0] != 0
    rhs = rng.standard_normal((6 * n_blocks, n_rhs))
    solved = rhs.copy()
    block_lu_solve(blocks, pivots, solved)
    _close(solved, np.linalg.solve(dense, rhs))


@pytest.mark.parametrize('width, unknown, entry', [
    (1, 0, 0.0), (1, 20, 0.0), (2, 35, 0.0), (2, 59, 0.0), (1, 13, np.nan), (2, 40, np.inf)])
def test_block_lu_stops_at_a_zero_or_non_finite_pivot(width, unknown, entry):
    """
    A zero column ``p`` (a singular matrix), or a non-finite entry on the diagonal at ``p``.

    The column stays zero (or non-finite) through the elimination of the ones before it, so
    block_lu stops at ``p``: it returns ``p + 1``.
    """
    rng = np.random.default_rng(unknown)
    dense = _block_banded(rng, 10, width)
    if entry == 0.0:
        dense[:, unknown] = 0.0
    else:
        dense[unknown, unknown] = entry
    pivots = np.zeros((10, 6), dtype=np.int64)
    assert block_lu(_exact_storage(dense, width), pivots) == unknown + 1


@pytest.mark.parametrize('name', ['tendon_6f_8c', 'cbha'])
def test_block_lu_solves_the_exact_tangent_of_a_scene_and_refuses_a_singular_one(name):
    """
    The block LU of the exact (non-symmetric) tangent solves the numpy oracle's dense tangent.

    The tendon trunk's cables span two links (B = 2), the CBHA's cavities one (B = 1). A chain
    whose last link has no stiffness, with slack tendons and no pressure, leaves its last frame
    free: a zero block column, refused at the last frame's first unknown.
    """
    scene = load_scene(name)
    model, n, m = scene.model, scene.model.n_links, len(scene.actuator_names)
    rng = np.random.default_rng(4)
    state = retract(rest_state(model), 0.05 * rng.standard_normal((n, 6)))
    actuation = scene.upper_bounds * rng.uniform(0.2, 0.7, m)
    system = EquilibriumSystem(model, scene.actuators, np.zeros(6 * n))
    assert system.block_width == (2 if name.startswith('tendon') else 1)
    system.evaluate(state.positions, state.rotations, actuation)
    exact = (assemble_tangent(model, state).to_dense(exact=True)
             + oracle(scene.actuators).load_tangent(state.positions, state.rotations, actuation,
                                                    symmetric=False))
    assert np.abs(exact - exact.T).max() > 1e-3 * np.abs(exact).max()   # not symmetric
    factor = system.factor_exact()
    assert factor.method == 'block_lu'
    rhs = rng.standard_normal((6 * n, 3))
    np.testing.assert_allclose(exact @ factor.solve(rhs), rhs, atol=1e-9)
    stiffness = np.array(model.stiffnesses)
    stiffness[-1] = 0.0
    free_end = EquilibriumSystem(model, scene.actuators, np.zeros(6 * n), stiffness=stiffness)
    free_end.evaluate(state.positions, state.rotations, np.zeros(m))
    assert not free_end.dense_exact(free_end.exact_tangent())[:, -6:].any()
    assert free_end.factor_exact() is None
    assert evaluation.factor_exact(free_end.record) == 6 * (n - 1) + 1


def test_retract_frames_and_exp_match_reference():
    rng = np.random.default_rng(3)
    model = _chain(5)
    state = retract(rest_state(model), 0.2 * rng.standard_normal((5, 6)))
    inc = np.concatenate([rng.standard_normal((5, 3)), [[0, 0, 0], [1e-9, 0, 0]]
                          + list(rng.standard_normal((3, 3)))], axis=1)
    pos, rot = retract_frames(state.positions, state.rotations, inc)
    ref = retract(state, inc)
    np.testing.assert_allclose(pos, ref.positions, atol=1e-15)
    np.testing.assert_allclose(rot, ref.rotations, atol=1e-14)
    v = rng.standard_normal((4, 3))
    np.testing.assert_allclose(exp_rotations(v), so3_exp(v), atol=1e-14)


@pytest.mark.parametrize('name', ['tendon_6f_8c', 'cbha'])
def test_solver_fallbacks_factor_the_exact_and_the_material_tangent(name, monkeypatch):
    """Block LU of the exact structure + load tangent; block Cholesky of the material one next."""
    scene = load_scene(name)
    model, n, m = scene.model, scene.model.n_links, len(scene.actuator_names)
    rng = np.random.default_rng(8)
    state = retract(rest_state(model), np.concatenate(
        [0.002 * rng.standard_normal((n, 3)), 0.2 * rng.standard_normal((n, 3))], axis=1))
    positions, rotations = state.positions, state.rotations
    actuation = scene.upper_bounds * rng.uniform(0.2, 0.7, m)
    rhs = rng.standard_normal((6 * n, m + 1))
    solver = scene.make_inverse_solver()
    exact = (assemble_tangent(model, ChainState(positions, rotations)).to_dense(exact=True)
             + oracle(scene.actuators).load_tangent(positions, rotations, actuation,
                                                    symmetric=False))
    factor = next(solver._system.fallback_factors(positions, rotations, actuation))
    assert factor.method == 'block_lu'
    np.testing.assert_allclose(exact @ factor.solve(rhs), rhs, atol=1e-9)

    def singular(self):
        return None

    monkeypatch.setattr(EquilibriumSystem, 'factor_exact', singular)
    material = blocks_to_dense(*material_tangent(model, ChainState(positions, rotations)))
    factor = next(solver._system.fallback_factors(positions, rotations, actuation))
    assert factor.method == 'block_cholesky'
    np.testing.assert_allclose(material @ factor.solve(rhs), rhs, atol=1e-9)


@pytest.mark.parametrize('name', ['tendon_6f_8c', 'cbha'])
def test_ticks_through_the_fallback_factorization_still_reach_the_target(name, monkeypatch):
    """The tick's Cholesky refused every time: the LU fallback path still converges (0.1 mm)."""
    scene = load_scene(name)
    rng = np.random.default_rng(21)
    m = len(scene.actuator_names)
    actuation = scene.lower_bounds + (scene.upper_bounds - scene.lower_bounds) * rng.uniform(
        0.0, 0.5, m)
    target = scene.forward(actuation, strict=True).effector_positions
    solver = scene.make_inverse_solver()
    methods = []
    chain = solver._system.fallback_factors

    def counted(*args, **kwargs):
        for factor in chain(*args, **kwargs):
            methods.append(factor.method)
            yield factor

    refuse_cholesky(solver, monkeypatch)
    monkeypatch.setattr(solver._system, 'fallback_factors', counted)
    statuses = [solver.step(target).status for _ in range(30)]
    out = solver.step(target)
    # from rest the first steps leave equilibrium, and the state says so until it converges
    assert set(statuses[:5]) <= {'solved', 'saturated', 'not_converged'}
    assert set(statuses[5:] + [out.status]) <= {'solved', 'saturated'}
    # every linearisation (one per tick, more while the state converges) by the exact tangent
    assert len(methods) >= 31 and set(methods) == {'block_lu'}
    reached = scene.forward(out.actuation, initial_state=solver.state, strict=True)
    assert np.linalg.norm(reached.effector_positions - target, axis=1).max() < 1e-4


def test_a_tick_without_any_factorization_holds_the_actuation(monkeypatch):
    """The Cholesky refused, the exact and the material tangents too: the tick holds."""
    scene = load_scene('tendon_6f_8c')
    solver = scene.make_inverse_solver()
    for _ in range(2):
        # the second tick's small step leaves the next linearisation to the held tick
        first = solver.step(scene.workspace_center + 0.002)
    state = solver.state
    refuse_cholesky(solver, monkeypatch)
    monkeypatch.setattr(solver._system, 'factor', lambda tangent=None: None)
    monkeypatch.setattr(solver._system, 'factor_exact', lambda: None)
    held = solver.step(scene.workspace_center - 0.002)
    assert held.status == 'not_positive_definite'
    np.testing.assert_array_equal(held.actuation, first.actuation)
    np.testing.assert_array_equal(solver.state.positions, state.positions)
    assert np.isfinite(held.effector_positions).all()


def test_between_linearisations_the_effector_positions_are_the_linear_prediction():
    """relinearize_every 5: the compiled tick writes targets + the predicted gap (paper eq. 11)."""
    scene = load_scene('cbha')
    solver = scene.make_inverse_solver(relinearize_every=5)
    phase = 2.0 * np.pi * np.arange(8) / 200
    for c, s in zip(np.cos(phase), np.sin(phase)):
        target = scene.workspace_center + np.array([0.0, 0.002 * c, 0.002 * s])
        result = solver.step(target)
        # the first tick starts from the rest shape, not the equilibrium under gravity
        assert result.status in ('solved', 'saturated', 'not_converged')
        np.testing.assert_array_equal(result.effector_positions,
                                      target + solver._data.gap.reshape(-1, 3))
        # the result's own copy, not the tick data's buffer
        assert not np.shares_memory(result.effector_positions, solver._data.effector_positions)
