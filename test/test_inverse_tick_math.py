"""Tick helpers (Jl⁻¹ series, retraction, dense LU) and the solver's fallback factorizations."""

from cbha_inverse.core import control
from cbha_inverse.core.assembly import assemble_tangent, blocks_to_dense, material_tangent
from cbha_inverse.core.chain import ChainModel, ChainState, rest_state, retract
from cbha_inverse.core.links import timoshenko_compliance
from cbha_inverse.core.se3 import so3_exp
from cbha_inverse.core.tick_math import DenseLU, exp_rotations, jl_coefficients, retract_frames
from cbha_inverse.paths import config_path
from cbha_inverse.scene import load_scene
import numpy as np
import pytest


def _chain(n):
    c = timoshenko_compliance(0.02, 2e7, 0.45, 0.006)
    return ChainModel.from_compliances(np.broadcast_to(c, (n, 6, 6)),
                                       np.tile([0.02, 0, 0], (n, 1)))


def test_jl_coefficients_are_continuous_at_the_switch():
    theta = np.array([0.5 - 1e-12, 0.5])
    c, dc = jl_coefficients(theta, theta * theta)
    assert c[0] == pytest.approx(c[1], rel=1e-11)
    assert dc[0] == pytest.approx(dc[1], rel=1e-8)
    c0, _ = jl_coefficients(np.array([0.0]), np.array([0.0]))
    assert c0[0] == pytest.approx(1.0 / 12.0)


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


def test_dense_lu_solves_and_detects_singular():
    rng = np.random.default_rng(4)
    a = rng.standard_normal((12, 12)) + 12 * np.eye(12)
    rhs = rng.standard_normal((12, 3))
    np.testing.assert_allclose(a @ DenseLU(a).solve(rhs), rhs, atol=1e-10)
    bad = a.copy()
    bad[:, 7] = 0.0
    with pytest.raises(np.linalg.LinAlgError, match='singular'):
        DenseLU(bad)


@pytest.mark.parametrize('name', ['tendon_6f_8c', 'cbha'])
def test_solver_fallbacks_factor_the_exact_and_the_material_tangent(name, monkeypatch):
    """LU of the exact structure + load tangent; BTD Cholesky of the material one if LU fails."""
    if name == 'cbha' and not config_path('segments', 'cbha_segment.yaml').is_file():
        pytest.skip('the condensed CBHA segment is not generated yet')
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
             + scene.actuators.load_tangent(positions, rotations, actuation, symmetric=False))
    factor = solver._factor(positions, rotations, actuation)
    assert factor.method == 'dense_lu'
    np.testing.assert_allclose(exact @ factor.solve(rhs), rhs, atol=1e-9)

    def singular(matrix):
        raise np.linalg.LinAlgError('singular')

    monkeypatch.setattr(control, 'DenseLU', singular)
    material = blocks_to_dense(*material_tangent(model, ChainState(positions, rotations)))
    factor = solver._factor(positions, rotations, actuation)
    np.testing.assert_allclose(material @ factor.solve(rhs), rhs, atol=1e-9)
