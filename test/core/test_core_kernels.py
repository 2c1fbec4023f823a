"""Kernels (Jl⁻¹, log/exp, retraction, band Cholesky), band LU and the solver's fallbacks."""

from cbha_inverse.core._kernels.band import (_backward_columns, _cholesky_width12,
                                             _forward_columns, band_cholesky,
                                             band_cholesky_forward, band_cholesky_profiled,
                                             band_forward,
                                             band_forward_profiled, band_solve, frame_profile)
from cbha_inverse.core._kernels.retraction import retract_frames
from cbha_inverse.core._kernels.so3 import jl_coefficient, rotation_exp, rotation_log
from cbha_inverse.core.chain import ChainModel, ChainState, rest_state, retract
from cbha_inverse.core.inverse import solver as control
from cbha_inverse.core.links import timoshenko_compliance
from cbha_inverse.scene import load_scene
import numpy as np
from oracles.actuation import oracle
from oracles.chain_forces import assemble_tangent, blocks_to_dense, material_tangent
from oracles.so3 import _jl_inv_coefficient, so3_exp, so3_log
import pytest


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


# kd = 11 with 7 or 9 right-hand sides and kd = 17 with 9 run the constant-trip-count sweeps of
# band_solve (FORWARD_COLUMN_COUNTS, BACKWARD_COLUMN_COUNTS), the others its general loops;
# kd = 11 and 17 the constant-trip-count Cholesky
@pytest.mark.parametrize('size, kd, n_rhs', [
    (1, 0, 5), (12, 11, 5), (36, 17, 5), (96, 11, 5), (20, 19, 5), (96, 11, 7), (96, 11, 9),
    (12, 11, 7), (36, 11, 9), (96, 11, 17), (96, 11, 1), (36, 17, 9), (60, 17, 17),
    (18, 17, 9)])
def test_band_cholesky_equals_dense_solve(size, kd, n_rhs):
    rng = np.random.default_rng(size + kd + n_rhs)
    a = rng.standard_normal((size, size))
    r, c = np.indices((size, size))
    a = np.where(np.abs(r - c) <= kd, a @ a.T + size * np.eye(size), 0.0)
    band = np.zeros((size, kd + 1))
    for d in range(kd + 1):
        band[:size - d, d] = np.diagonal(a, -d)
    assert band_cholesky(band) == 0
    lower = np.zeros((size, size))
    for d in range(kd + 1):
        lower += np.diag(band[:size - d, d], -d)
    np.testing.assert_allclose(lower, np.linalg.cholesky(a), atol=1e-12 * size)
    # a strided right-hand side (the columns after the first)
    rhs = rng.standard_normal((size, n_rhs + 1))
    solved = rhs.copy()
    band_solve(band, solved[:, 1:])
    np.testing.assert_allclose(solved[:, 1:], np.linalg.solve(a, rhs[:, 1:]), atol=1e-11)
    np.testing.assert_array_equal(solved[:, 0], rhs[:, 0])


@pytest.mark.parametrize('n_rhs', [7, 9, 5])
def test_band_kernels_on_the_frame_profile_equal_the_full_band(n_rhs):
    # a block-tridiagonal matrix of 6 x 6 blocks: band_cholesky and band_solve skip the zeros
    # outside its profile (frame_profile); the result is that of the full-band loops, bit for bit
    rng = np.random.default_rng(n_rhs)
    size = 48
    r, c = np.indices((size, size))
    a = rng.standard_normal((size, size))
    a = np.where(np.abs(r // 6 - c // 6) <= 1, a @ a.T + size * np.eye(size), 0.0)
    band = np.zeros((size, 12))
    for d in range(12):
        band[:size - d, d] = np.diagonal(a, -d)
    assert frame_profile(band)
    full = band.copy()
    assert _cholesky_width12(full) == 0
    assert band_cholesky(band) == 0
    np.testing.assert_array_equal(band, full)
    assert frame_profile(band)
    rhs = rng.standard_normal((size, n_rhs))
    solved, expected = rhs.copy(), rhs.copy()
    band_solve(band, solved)
    _forward_columns(full, expected, n_rhs, 12, 0)
    _backward_columns(full, expected, n_rhs, 12)
    np.testing.assert_array_equal(solved, expected)
    np.testing.assert_allclose(solved, np.linalg.solve(a, rhs), atol=1e-11)
    # one entry outside the profile (or a NaN) and the full band runs
    band[1, 11] = 1e-3
    assert not frame_profile(band)
    band[1, 11] = np.nan
    assert not frame_profile(band)
    assert not frame_profile(np.zeros((42, 11)))


def _frame_band(rng, size, broken=False):
    """Return a random SPD block-tridiagonal matrix of 6 x 6 blocks and its lower band."""
    r, c = np.indices((size, size))
    a = rng.standard_normal((size, size))
    a = np.where(np.abs(r // 6 - c // 6) <= 1, a @ a.T + size * np.eye(size), 0.0)
    if broken:
        a[13, 2] = a[2, 13] = 0.5
    band = np.zeros((size, 12))
    for d in range(12):
        band[:size - d, d] = np.diagonal(a, -d)
    return a, band


@pytest.mark.parametrize('broken', [False, True])
def test_the_cholesky_hands_its_profile_check_to_the_sweeps(broken):
    """
    band_cholesky_profiled checks the block profile once, for the sweeps of its factor.

    A factor it marks profiled has the profile; one coupling outside it (row 2 reaching row 13)
    turns the flag off and the sweep runs the full band: both give the dense half-solve, as
    band_forward (which checks the factor itself) does, bit for bit.
    """
    rng = np.random.default_rng(3)
    size = 48
    _, band = _frame_band(rng, size, broken)
    assert frame_profile(band) is not broken
    info, profiled = band_cholesky_profiled(band)
    assert info == 0 and profiled is not broken
    assert frame_profile(band) is profiled
    lower = np.zeros((size, size))
    for d in range(12):
        lower += np.diag(band[:size - d, d], -d)
    for n_rhs in (7, 3, 5):
        rhs = rng.standard_normal((size, n_rhs))
        rhs[:12] = 0.0
        solved, checked = rhs.copy(), rhs.copy()
        band_forward_profiled(band, solved, 12, profiled)
        band_forward(band, checked, 12)
        np.testing.assert_array_equal(solved, checked)
        np.testing.assert_allclose(solved, np.linalg.solve(lower, rhs), atol=1e-12)


@pytest.mark.parametrize('broken', [False, True])
@pytest.mark.parametrize('n_rhs, zero_from, zero_rows', [
    (7, 4, 42), (7, 4, 40), (7, 5, 30), (7, 7, 0), (9, 6, 42), (3, 0, 0), (5, 2, 18)])
def test_the_cholesky_with_its_sweep_equals_the_factor_then_the_sweep(broken, n_rhs, zero_from,
                                                                      zero_rows):
    """
    band_cholesky_forward gives band_cholesky_profiled then band_forward_profiled, bit for bit.

    Trailing columns zero down to some row (the J_aᵀ of a later section's actuators; a block
    boundary or not) are swept from there on; the rows above stay zero. A band off the frame
    profile is factored, then swept. Both give the dense half-solve.
    """
    rng = np.random.default_rng(n_rhs + zero_rows)
    size = 96
    a, band = _frame_band(rng, size, broken)
    rhs = rng.standard_normal((size, n_rhs))
    rhs[:zero_rows, zero_from:] = 0.0
    fused, solved = band.copy(), rhs.copy()
    info, profiled = band_cholesky_forward(fused, solved)
    assert info == 0 and profiled is not broken
    expected_band, expected = band.copy(), rhs.copy()
    assert band_cholesky_profiled(expected_band) == (0, profiled)
    band_forward_profiled(expected_band, expected, 0, profiled)
    np.testing.assert_array_equal(fused, expected_band)
    np.testing.assert_array_equal(solved, expected)
    np.testing.assert_allclose(solved, np.linalg.solve(np.linalg.cholesky(a), rhs), atol=1e-12)
    assert not solved[:zero_rows, zero_from:].any()


@pytest.mark.parametrize('n_rhs', [7, 5])
def test_the_cholesky_with_its_sweep_reports_the_failing_column(n_rhs):
    rng = np.random.default_rng(5)
    _, band = _frame_band(rng, 48)
    band[20, 0] = -1.0
    rhs = rng.standard_normal((48, n_rhs))
    expected_band = band.copy()
    info, profiled = band_cholesky_forward(band, rhs)
    assert (info, profiled) == band_cholesky_profiled(expected_band)
    assert info == 21 and profiled


def test_band_cholesky_reports_the_first_bad_pivot():
    a = np.diag([2.0, 3.0, -1.0, 4.0])
    band = np.zeros((4, 2))
    band[:, 0] = np.diag(a)
    assert band_cholesky(band) == 3
    band[:, 0] = [1.0, np.nan, 1.0, 1.0]
    assert band_cholesky(band) == 2


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


def test_band_lu_solves_the_exact_tangent_and_detects_singular():
    """LAPACK band LU of the exact (non-symmetric) tangent: solves; a zero column is refused."""
    scene = load_scene('tendon_6f_8c')
    model, n, m = scene.model, scene.model.n_links, len(scene.actuator_names)
    rng = np.random.default_rng(4)
    state = retract(rest_state(model), 0.05 * rng.standard_normal((n, 6)))
    actuation = scene.upper_bounds * rng.uniform(0.2, 0.7, m)
    system = control.EquilibriumSystem(model, scene.actuators, np.zeros(6 * n))
    tangent, _ = system.exact_system(state.positions, state.rotations, actuation)
    dense = system.dense_exact(tangent)
    assert np.abs(dense - dense.T).max() > 1e-3 * np.abs(dense).max()   # not symmetric
    rhs = rng.standard_normal((6 * n, 3))
    np.testing.assert_allclose(dense @ system.factor_exact(tangent).solve(rhs), rhs, atol=1e-9)
    tangent, _ = system.exact_system(state.positions, state.rotations, actuation)
    tangent[7] = 0.0    # column 7 of the matrix (general band storage, C order)
    assert system.factor_exact(tangent) is None


@pytest.mark.parametrize('name', ['tendon_6f_8c', 'cbha'])
def test_solver_fallbacks_factor_the_exact_and_the_material_tangent(name, monkeypatch):
    """LU of the exact structure + load tangent; BTD Cholesky of the material one if LU fails."""
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
    factor = next(solver._tick.fallback_factors(positions, rotations, actuation))
    assert factor.method == 'band_lu'
    np.testing.assert_allclose(exact @ factor.solve(rhs), rhs, atol=1e-9)

    def singular(self, tangent):
        return None

    monkeypatch.setattr(control.EquilibriumSystem, 'factor_exact', singular)
    material = blocks_to_dense(*material_tangent(model, ChainState(positions, rotations)))
    factor = next(solver._tick.fallback_factors(positions, rotations, actuation))
    assert factor.method == 'band_cholesky'
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
    calls = []
    chain = solver._tick.fallback_factors

    def counted(*args, **kwargs):
        calls.append(1)
        return chain(*args, **kwargs)

    monkeypatch.setattr(solver._tick, 'tick_cholesky', False)
    monkeypatch.setattr(solver._tick, 'fallback_factors', counted)
    for _ in range(30):
        out = solver.step(target)
        assert out.status in ('solved', 'saturated')
    assert len(calls) == 30
    reached = scene.forward(out.actuation, initial_state=solver.state, strict=True)
    assert np.linalg.norm(reached.effector_positions - target, axis=1).max() < 1e-4


def test_a_tick_without_any_factorization_holds_the_actuation(monkeypatch):
    scene = load_scene('tendon_6f_8c')
    solver = scene.make_inverse_solver()
    first = solver.step(scene.workspace_center + 0.002)
    state = solver.state
    monkeypatch.setattr(solver._tick, 'tick_cholesky', False)
    monkeypatch.setattr(solver._tick, 'factor', lambda tangent: None)
    monkeypatch.setattr(solver._tick, 'factor_exact', lambda tangent: None)
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
        assert result.status in ('solved', 'saturated')
        np.testing.assert_array_equal(result.effector_positions,
                                      target + solver._data.gap.reshape(-1, 3))
        # the result's own copy, not the tick data's buffer
        assert not np.shares_memory(result.effector_positions, solver._data.effector_positions)
