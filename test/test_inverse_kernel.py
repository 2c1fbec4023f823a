"""The fused tick kernel against the reference assembly, retract and BTD conventions."""

from cbha_inverse.core.assembly import assemble_tangent, blocks_to_dense, internal_wrenches
from cbha_inverse.core.chain import ChainModel, rest_state, retract
from cbha_inverse.core.kernel import (ChainKernel, DenseCholesky, fast_retract, fast_so3_exp,
                                      jl_inverse_coefficients)
from cbha_inverse.core.links import timoshenko_compliance
from cbha_inverse.core.se3 import so3_exp
import numpy as np
import pytest


def _chain(n, rng, rest_rotations=False):
    c = timoshenko_compliance(0.02, 2e7, 0.45, 0.006)
    rots = so3_exp(0.1 * rng.standard_normal((n, 3))) if rest_rotations else None
    return ChainModel.from_compliances(np.broadcast_to(c, (n, 6, 6)),
                                       np.tile([0.02, 0, 0], (n, 1)), rest_rotations=rots)


@pytest.mark.parametrize('n, rest_rotations, angle',
                         [(6, False, 0.3), (10, True, 0.3), (16, False, 1.2)])
def test_kernel_equals_reference_assembly(n, rest_rotations, angle):
    rng = np.random.default_rng(n)
    model = _chain(n, rng, rest_rotations)
    inc = np.concatenate([0.002 * rng.standard_normal((n, 3)),
                          angle * rng.standard_normal((n, 3))], axis=1)
    state = retract(rest_state(model), inc)
    reference = assemble_tangent(model, state)
    kernel = ChainKernel(model)
    internal, dense = kernel.linearise(state.positions, state.rotations)
    scale = np.abs(reference.internal).max()
    np.testing.assert_allclose(internal, reference.internal, atol=1e-12 * scale)
    np.testing.assert_allclose(kernel.internal(state.positions, state.rotations),
                               internal_wrenches(model, state), atol=1e-12 * scale)
    expected = blocks_to_dense(reference.diagonal, reference.upper)
    np.testing.assert_allclose(dense, expected, atol=1e-11 * np.abs(expected).max())


def test_jl_coefficients_are_continuous_at_the_switch():
    c, dc = jl_inverse_coefficients(np.array([0.5 - 1e-12, 0.5]))
    assert c[0] == pytest.approx(c[1], rel=1e-11)
    assert dc[0] == pytest.approx(dc[1], rel=1e-8)
    c0, _ = jl_inverse_coefficients(np.array([0.0]))
    assert c0[0] == pytest.approx(1.0 / 12.0)


def test_fast_retract_and_exp_match_reference():
    rng = np.random.default_rng(3)
    model = _chain(5, rng)
    state = retract(rest_state(model), 0.2 * rng.standard_normal((5, 6)))
    inc = np.concatenate([rng.standard_normal((5, 3)), [[0, 0, 0], [1e-9, 0, 0]]
                          + list(rng.standard_normal((3, 3)))], axis=1)
    pos, rot = fast_retract(state.positions, state.rotations, inc)
    ref = retract(state, inc)
    np.testing.assert_allclose(pos, ref.positions, atol=1e-15)
    np.testing.assert_allclose(rot, ref.rotations, atol=1e-14)
    v = rng.standard_normal((4, 3))
    np.testing.assert_allclose(fast_so3_exp(v), so3_exp(v), atol=1e-14)


def test_dense_cholesky_solves_and_detects_indefinite():
    rng = np.random.default_rng(4)
    a = rng.standard_normal((12, 12))
    spd = a @ a.T + 12 * np.eye(12)
    rhs = rng.standard_normal((12, 3))
    np.testing.assert_allclose(spd @ DenseCholesky(spd.copy()).solve(rhs), rhs, atol=1e-10)
    bad = spd.copy()
    bad[7, 7] = -100.0
    with pytest.raises(np.linalg.LinAlgError, match='frame 2'):
        DenseCholesky(bad)
