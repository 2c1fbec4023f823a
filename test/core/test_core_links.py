"""Tests of the compliance links: Timoshenko closed form, rigid motion, equilibrium, FD tangent."""

from cbha_inverse.core import links, so3
from cbha_inverse.core._kernels import evaluation
from cbha_inverse.core._kernels import links as kernels
from cbha_inverse.core._kernels.records import make_record
from cbha_inverse.core._kernels.so3 import jl_coefficient, left_jacobian_inverse_into
from cbha_inverse.core.actuation.actuators import ActuatorSet
from cbha_inverse.core.chain import ChainModel
from cbha_inverse.core.system import EquilibriumSystem, nonzero_cavity_columns
import numpy as np
from oracles import chain_forces
import pytest


def _virtual_work_compliance(length, e_mod, nu, r_o, r_i, kappa):
    """Compliance by the unit-load method: C = int S^T D^-1 S ds (3-point Gauss, exact here)."""
    area = np.pi * (r_o ** 2 - r_i ** 2)
    inertia = np.pi * (r_o ** 4 - r_i ** 4) / 4.0
    g_mod = e_mod / (2 * (1 + nu))
    d_inv = np.diag([1 / (e_mod * area), 1 / (kappa * g_mod * area), 1 / (kappa * g_mod * area),
                     1 / (g_mod * 2 * inertia), 1 / (e_mod * inertia), 1 / (e_mod * inertia)])
    nodes, weights = np.polynomial.legendre.leggauss(3)
    comp = np.zeros((6, 6))
    for xi, wgt in zip(nodes, weights):
        s = 0.5 * length * (xi + 1)
        sec = np.eye(6)
        sec[3:, :3] = so3.hat([length - s, 0.0, 0.0])   # moment of the tip force about s
        comp += 0.5 * length * wgt * sec.T @ d_inv @ sec
    return comp


@pytest.mark.parametrize('r_i', [0.0, 0.006])
def test_timoshenko_against_unit_load_method(r_i):
    """The closed form equals the unit-load (virtual work) integral for solid and hollow."""
    args = (0.12, 2.0e9, 0.35, 0.01, r_i)
    kappa = links.cowper_shear_coefficient(0.35, 0.01, r_i)
    ref = _virtual_work_compliance(*args, kappa)
    np.testing.assert_allclose(links.timoshenko_compliance(*args), ref, rtol=1e-13,
                               atol=1e-13 * np.abs(ref).max())


def test_cowper_limits():
    """Cowper: solid 6(1+nu)/(7+6nu); thin-walled tube limit 2(1+nu)/(4+3nu)."""
    nu = 0.3
    assert links.cowper_shear_coefficient(nu, 1.0) == pytest.approx(6 * 1.3 / (7 + 1.8))
    assert links.cowper_shear_coefficient(nu, 1.0, 1.0 - 1e-9) == pytest.approx(
        2 * 1.3 / (4 + 0.9), rel=1e-8)


def _random_link(rng, twist=0.6, stretch=0.01):
    """Return a random deformed link: stiffness, rest transform and two frame poses."""
    comp = links.timoshenko_compliance(0.05, 1e7, 0.4, 0.01, 0.004)
    m = rng.normal(size=(6, 6)) * 0.2
    stiff = np.linalg.inv(comp)
    scale = np.sqrt(np.diag(stiff))
    stiff = stiff + (m @ m.T) * np.outer(scale, scale)   # generic full SPD coupling
    d0 = np.array([0.05, 0.003, -0.002])
    q0 = so3.so3_exp(rng.normal(size=3) * 0.2)
    x_a = rng.normal(size=3) * 0.1
    r_a = so3.so3_exp(rng.normal(size=3) * 2.0)
    x_b = x_a + r_a @ d0 + stretch * rng.normal(size=3)
    r_b = so3.so3_exp(twist * rng.normal(size=3)) @ r_a @ q0
    return stiff, d0, q0, x_a, r_a, x_b, r_b


def test_rigid_motion_gives_zero_wrench_and_covariance():
    """At rest any rigid motion gives zero wrench; a deformed link's wrenches move with it."""
    rng = np.random.default_rng(5)
    stiff, d0, q0, x_a, r_a, _, _ = _random_link(rng)
    x_b, r_b = x_a + r_a @ d0, r_a @ q0
    w_a, w_b = chain_forces.link_wrenches(stiff, d0, q0, x_a, r_a, x_b, r_b)
    assert np.abs(w_a).max() < 1e-9 and np.abs(w_b).max() < 1e-9
    stiff, d0, q0, x_a, r_a, x_b, r_b = _random_link(rng)
    w_a, w_b = chain_forces.link_wrenches(stiff, d0, q0, x_a, r_a, x_b, r_b)
    rot, shift = so3.so3_exp([0.4, -1.2, 2.0]), np.array([0.3, -0.1, 2.0])
    v_a, v_b = chain_forces.link_wrenches(stiff, d0, q0, rot @ x_a + shift, rot @ r_a,
                                          rot @ x_b + shift, rot @ r_b)
    for w, v in ((w_a, v_a), (w_b, v_b)):
        np.testing.assert_allclose(v[:3], rot @ w[:3], atol=1e-9 * np.abs(w).max())
        np.testing.assert_allclose(v[3:], rot @ w[3:], atol=1e-9 * np.abs(w).max())


def test_wrenches_in_equilibrium_and_linear_response():
    """Sum of forces and of moments about a common point vanish; small strain gives -K delta."""
    rng = np.random.default_rng(6)
    for _ in range(5):
        stiff, d0, q0, x_a, r_a, x_b, r_b = _random_link(rng)
        w_a, w_b = chain_forces.link_wrenches(stiff, d0, q0, x_a, r_a, x_b, r_b)
        scale = np.abs(w_b).max()
        np.testing.assert_allclose(w_a[:3] + w_b[:3], 0.0, atol=1e-12 * scale)
        point = rng.normal(size=3)
        moment = (w_a[3:] + np.cross(x_a - point, w_a[:3])
                  + w_b[3:] + np.cross(x_b - point, w_b[:3]))
        np.testing.assert_allclose(moment, 0.0, atol=1e-12 * scale)
    stiff, d0, q0, x_a, r_a, _, _ = _random_link(rng)
    delta = 1e-7 * rng.normal(size=6)
    x_b = x_a + r_a @ (d0 + delta[:3])
    r_b = r_a @ so3.so3_exp(delta[3:]) @ q0
    _, w_b = chain_forces.link_wrenches(stiff, d0, q0, x_a, r_a, x_b, r_b)
    local = np.concatenate([r_a.T @ w_b[:3], r_a.T @ w_b[3:]])
    np.testing.assert_allclose(local, -stiff @ delta, rtol=1e-6, atol=1e-6 * np.abs(
        stiff @ delta).max())


@pytest.mark.parametrize('seed,twist', [(7, 0.0), (8, 0.05), (9, 0.6), (10, 1.5), (11, 2.5)])
def test_tangent_matches_central_differences(seed, twist):
    """The exact 12x12 tangent equals central differences with retract-style perturbations."""
    rng = np.random.default_rng(seed)
    stiff, d0, q0, x_a, r_a, x_b, r_b = _random_link(rng, twist=twist)

    def wrenches(dq):
        pose = (x_a + dq[:3], so3.so3_exp(dq[3:6]) @ r_a, x_b + dq[6:9],
                so3.so3_exp(dq[9:]) @ r_b)
        return np.concatenate(chain_forces.link_wrenches(stiff, d0, q0, *pose))

    tangent = chain_forces.link_tangent(stiff, d0, q0, x_a, r_a, x_b, r_b)
    h = 1e-6
    fd = np.stack([-(wrenches(h * e) - wrenches(-h * e)) / (2 * h) for e in np.eye(12)], -1)
    assert np.abs(tangent - fd).max() <= 1e-6 * np.abs(fd).max()
    np.testing.assert_allclose(tangent[:6, 6:], tangent[6:, :6].T, atol=1e-12 * np.abs(
        tangent).max())
    # rotational diagonal blocks: antisymmetric part hat(m)/2, m the link moment on the frame
    w_a, w_b = chain_forces.link_wrenches(stiff, d0, q0, x_a, r_a, x_b, r_b)
    for k, w in ((3, w_a), (9, w_b)):
        block = tangent[k:k + 3, k:k + 3]
        np.testing.assert_allclose(block - block.T, so3.hat(w[3:]),
                                   atol=1e-9 * np.abs(tangent).max())


def test_batched_matches_single():
    """Batched evaluation equals one-by-one evaluation."""
    rng = np.random.default_rng(12)
    items = [_random_link(rng) for _ in range(4)]
    stacked = [np.stack(col) for col in zip(*items)]
    t_batch = chain_forces.link_tangent(*stacked)
    for k, item in enumerate(items):
        np.testing.assert_allclose(t_batch[k], chain_forces.link_tangent(*item), rtol=1e-13,
                                   atol=1e-13 * np.abs(t_batch[k]).max())


def test_deformation_is_the_wrenches_delta():
    """``link_deformation`` gives the delta whose ``K delta`` the link terms carry."""
    stiff, d0, q0, x_a, r_a, x_b, r_b = _random_link(np.random.default_rng(11))
    delta = chain_forces.link_deformation(d0, q0, x_a, r_a, x_b, r_b)
    np.testing.assert_allclose(delta[:3], r_a.T @ (x_b - x_a) - d0, rtol=1e-13, atol=1e-16)
    np.testing.assert_allclose(so3.so3_exp(delta[3:]), r_a.T @ r_b @ q0.T, atol=1e-13)
    terms = chain_forces.link_terms(stiff, d0, q0, x_a, r_a, x_b, r_b)
    np.testing.assert_allclose(terms.stress, stiff @ delta, rtol=1e-12)


@pytest.mark.parametrize('seed, twist', [(21, 0.05), (22, 0.6), (23, 2.5)])
def test_the_link_equations_one_by_one_against_the_oracle(seed, twist):
    """
    The compiled link functions, one per paper equation, against the numpy oracle of the link.

    Eq. 4 (link_deformation), the inverse left Jacobian, eq. 5 (local_wrench), eq. 5-7
    (world_wrench, add_to_frame_b, add_to_frame_a: the oracle's world wrenches on both frames),
    eq. 8 with the stress and geometric terms (add_stress_terms, local_tangent, world_tangent,
    add_geometric_terms: the oracle's exact 12 x 12 tangent), the material part alone (the
    oracle's ``Bᵀ K B`` in world axes) and the symmetric part (symmetrize, then the symmetric
    world and geometric terms: the lower triangle of ``(T + Tᵀ) / 2``).
    """
    rng = np.random.default_rng(seed)
    stiff, d0, q0, x_a, r_a, x_b, r_b = _random_link(rng, twist=twist)
    link = 1
    positions = np.stack([rng.normal(size=3), x_a, x_b])
    rotations = np.stack([so3.so3_exp(rng.normal(size=3)), r_a, r_b])
    stiffness = np.stack([np.eye(6), stiff])
    rest_offsets = np.stack([np.zeros(3), d0])
    rest_rotations_t = np.ascontiguousarray(np.stack([np.eye(3), q0.T]))
    difference, relative, delta = np.empty(3), np.empty((3, 3)), np.empty(6)
    theta = kernels.link_deformation(positions, rotations, rest_offsets, rest_rotations_t, link,
                                     difference, relative, delta)
    expected = chain_forces.link_deformation(d0, q0, x_a, r_a, x_b, r_b)
    np.testing.assert_allclose(delta, expected, rtol=0, atol=1e-14)
    np.testing.assert_allclose(difference, x_b - x_a, rtol=0, atol=1e-16)
    np.testing.assert_allclose(relative, r_a.T @ r_b @ q0.T, rtol=0, atol=1e-15)
    assert theta == pytest.approx(np.linalg.norm(expected[3:]), rel=1e-13)
    jl_inverse = np.empty((3, 3))
    left_jacobian_inverse_into(delta[3:], theta, jl_coefficient(theta)[0], jl_inverse)
    terms = chain_forces.link_terms(stiff, d0, q0, x_a, r_a, x_b, r_b)
    np.testing.assert_allclose(jl_inverse, terms.jinv, rtol=0, atol=1e-14)

    def local_terms():
        stress, weighted, local = np.empty(6), np.empty((6, 6)), np.empty((6, 1))
        kernels.local_wrench(stiffness, link, delta, jl_inverse, stress, weighted, local)
        return stress, weighted, local

    stress, weighted, local = local_terms()
    scale = np.abs(terms.stress).max()
    np.testing.assert_allclose(stress, terms.stress, rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(local[:, 0], terms.wrench_b, rtol=0, atol=1e-13 * scale)
    world, rhs = np.empty((6, 1)), np.zeros((12, 1))
    kernels.world_wrench(rotations, link, local, 0, world)
    kernels.add_to_frame_b(world, 0, link, rhs)
    kernels.add_to_frame_a(world, 0, difference, link, rhs)
    w_a, w_b = chain_forces.link_wrenches(stiff, d0, q0, x_a, r_a, x_b, r_b)
    np.testing.assert_allclose(rhs[:, 0], np.concatenate([w_a, w_b]), rtol=0, atol=1e-13 * scale)

    def tangent_of(exact, symmetric):
        _, weighted, _ = local_terms()
        if exact:
            kernels.add_stress_terms(weighted, delta, stress, theta)
        tangent, block = np.empty((6, 6)), np.full((12, 12), np.nan)
        kernels.local_tangent(weighted, jl_inverse, tangent)
        if symmetric:
            kernels.symmetrize(tangent)
        kernels.world_tangent(tangent, rotations, link, difference, symmetric, block)
        if exact:
            kernels.add_geometric_terms(world, difference, symmetric, block)
        return block

    exact = chain_forces.link_tangent(stiff, d0, q0, x_a, r_a, x_b, r_b)
    scale = np.abs(exact).max()
    np.testing.assert_allclose(tangent_of(True, False), exact, rtol=0, atol=1e-12 * scale)
    material = chain_forces.rotate_tangent(r_a, chain_forces.local_material_tangent(terms, stiff))
    np.testing.assert_allclose(tangent_of(False, False), material, rtol=0, atol=1e-12 * scale)
    symmetric = np.tril(tangent_of(True, True))
    assert np.isfinite(symmetric).all()
    np.testing.assert_allclose(symmetric, np.tril(0.5 * (exact + exact.T)), rtol=0,
                               atol=1e-12 * scale)
    assert np.abs(exact - exact.T).max() > 1e-6 * scale


def _chain_record(rng, n, n_cavities, rest_twist=0.2):
    """
    Return an equilibrium record of ``n`` random links with random condensed-cavity terms.

    An :class:`EquilibriumSystem` of the links alone gives the record's fields; its cavity
    fields (``G0``, ``H``, their nonzero columns) and the buffers of their columns are replaced
    by random ones. Also returns the links and the cavity arrays.
    """
    items = [_random_link(rng) for _ in range(n)]
    stiffness = np.stack([item[0] for item in items])
    rest_offsets = np.stack([item[1] for item in items])
    rest_rotations = np.stack([so3.so3_exp(rest_twist * rng.normal(size=3)) for _ in range(n)])
    model = ChainModel.from_compliances(np.linalg.inv(stiffness), rest_offsets,
                                        rest_rotations=rest_rotations)
    system = EquilibriumSystem(model, ActuatorSet((), model.n_frames), np.zeros(6 * n),
                               stiffness=stiffness)
    wrench = rng.normal(size=(n, n_cavities, 6))
    hessian = rng.normal(size=(n, n_cavities, 6, 6)) * 100.0
    fields = {field.name: getattr(system.record, field.name)
              for field in evaluation.EQUILIBRIUM_FIELDS}
    fields.update(cavity_wrench=wrench, cavity_stiffness=hessian,
                  rhs=np.zeros((6 * n, n_cavities + 1)),
                  link_local=np.zeros((6, n_cavities + 1)),
                  link_world=np.zeros((6, n_cavities + 1)))
    return fields, model, stiffness


def _record(fields, columns):
    """Return the record of ``fields`` with these cavity columns per link (new buffers)."""
    fields = dict(fields, cavity_columns=columns, rhs=np.zeros_like(fields['rhs']),
                  values=np.zeros_like(fields['values']),
                  blocks=np.zeros_like(fields['blocks']))
    return make_record(evaluation.EquilibriumRecord, evaluation.new_equilibrium_record, **fields)


def _chain_pose(rng, model):
    """Return random frames near the rest shape of a chain."""
    n = model.n_links
    positions = np.cumsum(np.concatenate([np.zeros((1, 3)), model.rest_offsets]), axis=0)
    positions += rng.normal(scale=0.003, size=(n + 1, 3))
    rotations = so3.so3_exp(rng.normal(scale=0.3, size=(n + 1, 3)))
    return positions, rotations


def test_the_link_pass_of_a_chain_equals_the_oracle():
    """
    The link pass of a chain without cavities against the oracle's links.

    The oracle's link wrenches gathered on frames 1..n (the residual), and per link its exact
    or material 12 x 12 tangent in ``values``.
    """
    rng = np.random.default_rng(19)
    n = 4
    fields, model, stiffness = _chain_record(rng, n, 0)
    record = _record(fields, np.zeros((n, 0), dtype=np.int64))
    positions, rotations = _chain_pose(rng, model)
    args = (stiffness, model.rest_offsets, model.rest_rotations, positions[:-1], rotations[:-1],
            positions[1:], rotations[1:])
    w_a, w_b = chain_forces.link_wrenches(*args)
    internal = w_b.copy()
    internal[:-1] += w_a[1:]
    exact = chain_forces.link_tangent(*args)
    terms = chain_forces.link_terms(*args)
    material = chain_forces.rotate_tangent(rotations[:-1],
                                           chain_forces.local_material_tangent(terms, stiffness))
    for tangent, is_exact in ((exact, True), (material, False)):
        evaluation.evaluate(record, positions, rotations, np.zeros(0), is_exact, False)
        scale = np.abs(internal).max()
        np.testing.assert_allclose(record.rhs[:, 0], internal.reshape(-1), rtol=0,
                                   atol=1e-12 * scale)
        blocks = record.values[:144 * n].reshape(n, 12, 12)
        np.testing.assert_allclose(blocks, tangent, rtol=0, atol=1e-12 * np.abs(tangent).max())


def test_link_pass_skips_zero_cavity_columns_exactly():
    """Listing only the nonzero cavity columns gives the same wrenches and tangents, bitwise."""
    rng = np.random.default_rng(13)
    n, c = 4, 3
    fields, model, _ = _chain_record(rng, n, c)
    wrench, hessian = fields['cavity_wrench'], fields['cavity_stiffness']
    # link 0: cavity 1 only; link 1: none; link 2: G0 zero but H not; link 3: all three
    for link, cav in ((0, 0), (0, 2), (1, 0), (1, 1), (1, 2)):
        wrench[link, cav] = 0.0
        hessian[link, cav] = 0.0
    wrench[2, 0] = 0.0
    columns = nonzero_cavity_columns(wrench, hessian)
    np.testing.assert_array_equal(columns, [[1, -1, -1], [-1, -1, -1], [0, 1, 2], [0, 1, 2]])
    positions, rotations = _chain_pose(rng, model)
    actuation = rng.normal(size=c)
    every = np.tile(np.arange(c), (n, 1))
    results = []
    for listed in (columns, every):
        record = _record(fields, listed)
        for exact, into_band in ((True, False), (False, False), (True, True)):
            record.rhs[:] = np.nan
            evaluation.evaluate(record, positions, rotations, actuation, exact, into_band)
            results.append((record.rhs.copy(), record.values.copy(), record.blocks.copy()))
    for listed, everything in zip(results[:3], results[3:]):
        for got, expected in zip(listed, everything):
            assert np.all(np.isfinite(got))
            np.testing.assert_array_equal(got, expected)
    # the skipped columns of J_aᵀ are zero, the others are not
    assert np.all(results[0][0][:, 1:].any(axis=0))


def test_the_band_link_pass_adds_the_symmetric_part_of_the_exact_blocks():
    """
    The link pass into the block band: the lower triangle of ``(T + Tᵀ) / 2`` of its blocks ``T``.

    The links with condensed cavities (their wrenches and load stiffness), assembled densely
    from the exact blocks of ``values`` (the base frame left out) and compared to rounding (the
    band pass symmetrises before its products); the same wrenches and ``J_aᵀ``, bitwise; the
    base frame's rows and columns are left out (the trash row of the band stays zero).
    """
    rng = np.random.default_rng(17)
    n, c = 4, 3
    fields, model, _ = _chain_record(rng, n, c)
    fields['cavity_wrench'][1, 2] = fields['cavity_stiffness'][1, 2] = 0.0
    record = _record(fields, nonzero_cavity_columns(fields['cavity_wrench'],
                                                    fields['cavity_stiffness']))
    positions, rotations = _chain_pose(rng, model)
    actuation = rng.uniform(1e3, 1e5, c)
    size = 6 * n
    evaluation.evaluate(record, positions, rotations, actuation, True, False)
    rhs, blocks = record.rhs.copy(), record.values[:144 * n].reshape(n, 12, 12).copy()
    expected = np.zeros((size + 6, size + 6))
    for link in range(n):
        expected[6 * link:6 * link + 12, 6 * link:6 * link + 12] += blocks[link]
    expected = np.tril(0.5 * (expected + expected.T))[6:, 6:]
    record.rhs[:] = np.nan
    evaluation.evaluate(record, positions, rotations, actuation, True, True)
    got = np.zeros((size, size))
    for col in range(n):
        for offset in range(min(record.blocks.shape[1], n - col)):
            got[6 * (col + offset):6 * (col + offset + 1), 6 * col:6 * (col + 1)] = (
                record.blocks[col, offset])
    got = np.tril(got)
    assert np.abs(expected - expected.T).max() > 0.0  # lower triangle only
    assert np.abs(blocks - np.swapaxes(blocks, 1, 2)).max() > 1e-3 * np.abs(blocks).max()
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-14 * np.abs(expected).max())
    np.testing.assert_array_equal(record.rhs, rhs)
    assert not record.blocks[n].any()
