"""Actuator columns (cables, cavities) against finite differences and rigid-body invariants."""

from cbha_inverse.core.actuation.actuators import ActuatorSet
from cbha_inverse.core.actuation.cables import Cable, CableGroup
from cbha_inverse.core.actuation.cavities import Cavity, CavityGroup, CavityPart, tube_surface
from cbha_inverse.core.actuation.condensed_cavities import LinearCavityGroup
from cbha_inverse.core.actuation.effectors import PointEffectors
from cbha_inverse.core.chain import ChainModel, rest_state, retract
from cbha_inverse.core.links import timoshenko_compliance
from cbha_inverse.core.so3 import so3_exp
from cbha_inverse.core.system import EquilibriumSystem
import numpy as np
from oracles.actuation import oracle
from oracles.effectors import apply_effector_jacobian, effector_jacobian
import pytest

N_LINKS = 4
LENGTH = 0.03


def _model():
    c = timoshenko_compliance(LENGTH, 2e7, 0.45, 0.006)
    return ChainModel.from_compliances(np.broadcast_to(c, (N_LINKS, 6, 6)),
                                       np.tile([LENGTH, 0.0, 0.0], (N_LINKS, 1)))


def _deformed(rng, scale=0.15):
    inc = np.concatenate([0.02 * scale * rng.standard_normal((N_LINKS, 3)),
                          scale * rng.standard_normal((N_LINKS, 3))], axis=1)
    return retract(rest_state(_model()), inc)


def _cables():
    return [Cable('a', [0, 2, 4], [[0, 0.01, 0]] * 3, 5.0),
            Cable('b', [0, 1, 2, 3], [[0, -0.01, 0.004], [0, -0.01, 0.0], [0, -0.008, 0.0],
                                      [0, -0.01, 0.002]], 5.0),
            Cable('c', [0, 4, 4], [[0, 0, 0.012], [0, 0, 0.012], [0.002, 0.004, 0.0]], 5.0)]


def _cavities():
    points, tris = tube_surface(LENGTH, 0.004, (0.008, 0.003), n_around=12, n_along=3)
    parts = tuple(CavityPart(points, tris, i, np.array([LENGTH, 0, 0]), np.eye(3))
                  for i in (1, 2, 3))
    points2, tris2 = tube_surface(LENGTH, 0.003, (-0.006, -0.005), n_around=10, n_along=4)
    return [Cavity('p1', parts, 1.5e5),
            Cavity('p2', (CavityPart(points2, tris2, 0, np.array([LENGTH, 0, 0]), np.eye(3)),),
                   1.5e5)]


def _fd_check(group, state, rng, h=1e-6):
    """Assert ``J_a dq`` equals the central difference of ``δ_a`` along ``retract``."""
    wrenches, _ = oracle(group).evaluate(state.positions, state.rotations)
    for _ in range(3):
        dq = rng.standard_normal((N_LINKS, 6)) * [0.01, 0.01, 0.01, 1, 1, 1]
        plus = oracle(group).evaluate(*_pose(retract(state, h * dq)))[1]
        minus = oracle(group).evaluate(*_pose(retract(state, -h * dq)))[1]
        fd = (plus - minus) / (2 * h)
        analytic = np.einsum('mfa,fa->m', wrenches[:, 1:], dq)
        np.testing.assert_allclose(analytic, fd, rtol=1e-6, atol=1e-9 * np.abs(fd).max())


def _pose(state):
    return state.positions, state.rotations


def test_cable_column_is_virtual_work_of_shortening():
    rng = np.random.default_rng(1)
    group = CableGroup(_cables(), N_LINKS + 1)
    _fd_check(group, _deformed(rng), rng)


def test_cable_tension_pulls_end_toward_base():
    group = CableGroup([Cable('a', [0, 4], [[0, 0.01, 0], [0, 0.01, 0]], 1.0)], N_LINKS + 1)
    wrenches, shortening = oracle(group).evaluate(*_pose(rest_state(_model())))
    np.testing.assert_allclose(wrenches[0, 4], [-1, 0, 0, 0, 0, 0.01], atol=1e-12)
    assert shortening[0] == pytest.approx(-4 * LENGTH)


def test_cavity_mesh_column_is_virtual_work_of_volume():
    rng = np.random.default_rng(2)
    group = CavityGroup(_cavities(), N_LINKS + 1)
    _fd_check(group, _deformed(rng), rng)


def test_compiled_mesh_cavities_equal_the_numpy_oracle():
    """
    The compiled skinning, columns and volumes of a CavityGroup against the numpy oracle.

    Parts with rest rotations and offsets off the segment axis (the skinning weight clipped at
    both caps), gains other than 1, two cavities sharing frames, a deformed and a rigidly moved
    chain.
    """
    rng = np.random.default_rng(9)
    points, tris = tube_surface(LENGTH + 0.004, 0.004, (0.008, 0.003), n_around=9, n_along=4)
    points = points - [0.002, 0.0, 0.0]     # the caps beyond the frames: weights 0 and 1
    parts = tuple(CavityPart(points, tris, i, np.array([LENGTH, 0.002, -0.001]),
                             so3_exp(0.1 * rng.standard_normal(3))) for i in (0, 2, 3))
    cavities = _cavities()
    cavities = [Cavity('q', parts, 1e5, gain=0.8), cavities[0],
                Cavity('r', cavities[1].parts, 1e5, gain=1.3)]
    group = CavityGroup(cavities, N_LINKS + 1)
    reference = oracle(group)
    assert type(reference) is not CavityGroup
    rigid = retract(rest_state(_model()), np.tile([0.01, 0.0, 0.0, 0.2, -0.1, 0.3], (N_LINKS, 1)))
    for state in (_deformed(rng, 0.3), rigid):
        pose = _pose(state)
        for got, expected in zip(group.vertices(*pose), reference.vertices(*pose)):
            np.testing.assert_allclose(got, expected, rtol=0, atol=1e-15)
        wrenches, volumes = group.evaluate(*pose)
        expected_wrenches, expected_volumes = reference.evaluate(*pose)
        assert np.abs(expected_wrenches).max() > 0.0 and np.all(expected_volumes > 0.0)
        np.testing.assert_allclose(wrenches, expected_wrenches, rtol=0,
                                   atol=1e-13 * np.abs(expected_wrenches).max())
        np.testing.assert_allclose(volumes, expected_volumes, rtol=1e-12)
        np.testing.assert_allclose(group.volumes(*pose), expected_volumes, rtol=1e-12)
    # the gains scale the columns and the volumes
    unit = oracle(CavityGroup([Cavity('q', parts, 1e5)], N_LINKS + 1)).evaluate(*pose)
    np.testing.assert_allclose(0.8 * unit[0][0], wrenches[0], rtol=1e-12,
                               atol=1e-15 * np.abs(wrenches).max())
    assert 0.8 * unit[1][0] == pytest.approx(volumes[0], rel=1e-12)


def test_the_evaluation_puts_the_mesh_cavities_columns_and_loads_on_their_frames():
    """``J_aᵀ`` with mesh cavities: the oracle's wrenches, ``λ`` times them in ``r``."""
    rng = np.random.default_rng(4)
    model = _model()
    group = CavityGroup(_cavities(), N_LINKS + 1)
    system = EquilibriumSystem(model, ActuatorSet([group], model.n_frames), np.zeros(6 * N_LINKS))
    pose = _pose(_deformed(rng))
    wrenches, _ = oracle(group).evaluate(*pose)
    # frame f's wrench on rows 6 (f - 1) ... 6 f (the base frame is fixed)
    columns = wrenches[:, 1:].reshape(len(wrenches), -1).T
    pressures = np.array([4e4, 2e4])
    rhs = system.evaluate(*pose, pressures).copy()
    unloaded = system.evaluate(*pose, np.zeros(2))[:, 0].copy()
    scale = np.abs(columns).max()
    assert scale > 0.0
    np.testing.assert_allclose(rhs[:, 1:], columns, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(rhs[:, 0] - unloaded, columns @ pressures, rtol=0,
                               atol=1e-12 * scale * pressures.max())


def test_tube_volume_and_outward_orientation():
    points, tris = tube_surface(0.05, 0.01, (0.0, 0.0), n_around=64, n_along=5)
    part = CavityPart(points, tris, 0, np.array([0.05, 0, 0]), np.eye(3))
    group = CavityGroup([Cavity('t', (part,), 1.0)], 2)
    state = rest_state(ChainModel.from_compliances(
        timoshenko_compliance(0.05, 1e7, 0.4, 0.01)[None], [[0.05, 0, 0]]))
    volume = group.volumes(*_pose(state))[0]
    exact = 0.5 * 64 * 0.01 ** 2 * np.sin(2 * np.pi / 64) * 0.05
    assert volume == pytest.approx(exact, rel=1e-12)


@pytest.mark.parametrize('model_type', [CavityGroup, LinearCavityGroup])
def test_closed_cavity_gives_zero_net_wrench(model_type):
    rng = np.random.default_rng(3)
    group = model_type(_cavities(), N_LINKS + 1)
    rigid = retract(rest_state(_model()), np.tile(
        np.concatenate([[0.01, -0.02, 0.03], 0.4 * rng.standard_normal(3)]), (N_LINKS, 1)))
    rot = so3_exp(0.4 * rng.standard_normal(3))
    positions = rigid.positions @ rot.T + [0.1, 0.2, -0.1]
    rotations = rot @ rigid.rotations
    for pos, rots in [(positions, rotations), _pose(_deformed(rng))]:
        wrenches, _ = oracle(group).evaluate(pos, rots)
        scale = np.abs(wrenches[:, :, :3]).max()
        force = wrenches[:, :, :3].sum(axis=1)
        moment = (wrenches[:, :, 3:] + np.cross(pos[None], wrenches[:, :, :3])).sum(axis=1)
        np.testing.assert_allclose(force, 0.0, atol=1e-12 * scale)
        np.testing.assert_allclose(moment, 0.0, atol=1e-12 * scale)


def test_linear_cavity_matches_mesh_to_second_order():
    exact = CavityGroup(_cavities(), N_LINKS + 1)
    linear = LinearCavityGroup(_cavities(), N_LINKS + 1)
    rest = _pose(rest_state(_model()))
    reference = oracle(exact).evaluate(*rest)[0]
    np.testing.assert_allclose(oracle(linear).evaluate(*rest)[0], reference,
                               rtol=1e-9, atol=1e-9 * np.abs(reference).max())
    errors = []
    for scale in (0.1, 0.05):
        state = _deformed(np.random.default_rng(5), scale)
        a, b = oracle(linear).evaluate(*_pose(state))[0], oracle(exact).evaluate(*_pose(state))[0]
        errors.append(np.abs(a - b).max() / np.abs(b).max())
    print('relative error of the linear cavity model at 0.1 / 0.05 rad per frame:', errors)
    assert errors[0] < 2e-2
    assert errors[1] < errors[0] / 3.0


def test_actuator_set_orders_columns_and_loads():
    state = _deformed(np.random.default_rng(6))
    cables = CableGroup(_cables(), N_LINKS + 1)
    cavities = CavityGroup(_cavities(), N_LINKS + 1)
    both = ActuatorSet([cables, cavities], N_LINKS + 1, order=['p2', 'a', 'p1', 'b', 'c'])
    w, d = oracle(both).evaluate(*_pose(state))
    wc, dc = oracle(cables).evaluate(*_pose(state))
    wp, dp = oracle(cavities).evaluate(*_pose(state))
    np.testing.assert_array_equal(w[[1, 3, 4]], wc)
    np.testing.assert_array_equal(w[[2, 0]], wp)
    np.testing.assert_array_equal(both.upper_bounds, [1.5e5, 5, 1.5e5, 5, 5])
    a = np.array([1e4, 1.0, 2e4, 0.5, 0.0])
    np.testing.assert_allclose(oracle(both).loads(*_pose(state), a), np.einsum('m,mfa->fa', a, w))
    with pytest.raises(ValueError):
        ActuatorSet([cables], N_LINKS + 1, order=['a', 'b'])


def test_effector_points_are_frame_origin_plus_rotated_offset():
    """The points ``x_f + R_f o`` and levers ``R_f o``, against a product written by hand."""
    rng = np.random.default_rng(17)
    state = _deformed(rng, scale=0.4)
    offsets = [[0.0, 0.01, 0.0], [0.02, 0.0, -0.01], [0.0, 0.0, 0.0]]
    eff = PointEffectors(['mid', 'tip', 'centre'], [2, 4, 4], offsets, N_LINKS + 1)
    by_hand = np.array([state.positions[f] + state.rotations[f] @ np.array(o)
                        for f, o in zip([2, 4, 4], offsets)])
    np.testing.assert_allclose(eff.positions(*_pose(state)), by_hand, rtol=0, atol=1e-15)
    np.testing.assert_allclose(eff.levers(state.rotations), by_hand - state.positions[[2, 4, 4]],
                               rtol=0, atol=1e-15)
    assert np.array_equal(eff.positions(*_pose(state))[2], state.positions[4])


def test_effector_jacobian_matches_finite_differences():
    rng = np.random.default_rng(7)
    state = _deformed(rng)
    eff = PointEffectors(['mid', 'tip'], [2, 4], [[0, 0.01, 0], [0.02, 0, -0.01]], N_LINKS + 1)
    dq = rng.standard_normal((N_LINKS, 6))
    h = 1e-6
    fd = (eff.positions(*_pose(retract(state, h * dq)))
          - eff.positions(*_pose(retract(state, -h * dq)))) / (2 * h)
    np.testing.assert_allclose(apply_effector_jacobian(eff, state.rotations, dq), fd, rtol=1e-7,
                               atol=1e-10)
    np.testing.assert_allclose(effector_jacobian(eff, state.rotations) @ dq.reshape(-1),
                               fd.reshape(-1), rtol=1e-7, atol=1e-10)
    many = apply_effector_jacobian(eff, state.rotations, np.stack([dq, 2 * dq], axis=2))
    np.testing.assert_allclose(many[..., 1], 2 * many[..., 0])
    with pytest.raises(ValueError):
        PointEffectors(['base'], [0], [[0, 0, 0]], N_LINKS + 1)


@pytest.mark.parametrize('kind', ['cables', 'cavities'])
def test_load_stiffness_is_the_load_derivative_or_its_symmetric_part(kind):
    rng = np.random.default_rng(8)
    if kind == 'cables':
        group, amount = CableGroup(_cables(), N_LINKS + 1), np.array([2.0, 3.0, 1.5])
    else:
        group, amount = LinearCavityGroup(_cavities(), N_LINKS + 1), np.array([1e5, 7e4])
    state = _deformed(rng)
    h, n = 1e-6, N_LINKS
    fd = np.zeros((6 * n, 6 * n))
    for j in range(6 * n):
        e = np.zeros((n, 6))
        e.reshape(-1)[j] = h
        columns = oracle(group)
        plus = np.einsum('m,mfa->fa', amount, columns.evaluate(*_pose(retract(state, e)))[0])
        minus = np.einsum('m,mfa->fa', amount, columns.evaluate(*_pose(retract(state, -e)))[0])
        fd[:, j] = -(plus - minus)[1:].reshape(-1) / (2 * h)
    analytic = oracle(group).load_tangent(state.positions, state.rotations, amount)
    np.testing.assert_allclose(analytic, 0.5 * (fd + fd.T), atol=1e-7 * np.abs(fd).max())
    exact = oracle(group).load_tangent(state.positions, state.rotations, amount, symmetric=False)
    np.testing.assert_allclose(exact, fd, atol=1e-7 * np.abs(fd).max())
    # the skew part is far above the tolerance, so the comparison above would see it missing
    assert np.abs(exact - exact.T).max() > 100 * 1e-7 * np.abs(fd).max()
