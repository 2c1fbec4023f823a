"""Tests of the compliance links: Timoshenko closed form, rigid motion, equilibrium, FD tangent."""

from cbha_inverse.core import links, so3
from cbha_inverse.core._kernels.links import (link_pass, link_pass_band_into, link_work_size,
                                              nonzero_cavity_columns)
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


def test_link_pass_skips_zero_cavity_columns_exactly():
    """Listing only the nonzero cavity columns gives the same wrenches and tangents, bitwise."""
    rng = np.random.default_rng(13)
    n, c = 4, 3
    stiffness = np.stack([_random_link(rng)[0] for _ in range(n)])
    positions = np.cumsum(rng.normal(scale=0.02, size=(n + 1, 3)), axis=0)
    rotations = so3.so3_exp(rng.normal(scale=0.2, size=(n + 1, 3)))
    rest_offsets = rng.normal(scale=0.02, size=(n, 3))
    wrench = rng.normal(size=(n, c, 6))
    hessian = rng.normal(size=(n, c, 6, 6))
    # link 0: cavity 1 only; link 1: none; link 2: G0 zero but H not; link 3: all three
    for link, cav in ((0, 0), (0, 2), (1, 0), (1, 1), (1, 2)):
        wrench[link, cav] = 0.0
        hessian[link, cav] = 0.0
    wrench[2, 0] = 0.0
    # read-only as a scene holds them: the signature the warm-up compiled (no ~40 s compile)
    stiffness.flags.writeable = rest_offsets.flags.writeable = False
    columns = nonzero_cavity_columns(wrench, hessian)
    np.testing.assert_array_equal(columns, [[1, -1, -1], [-1, -1, -1], [0, 1, 2], [0, 1, 2]])
    actuation = rng.normal(size=c)
    every = np.tile(np.arange(c), (n, 1))
    results = []
    for listed in (columns, every):
        for material in (False, True):
            rhs = np.full((6 * n, c + 1), np.nan)
            blocks = np.full((n, 12, 12), np.nan)
            link_pass(positions, rotations, stiffness, rest_offsets, np.zeros((0, 3, 3)),
                      actuation, wrench, hessian, listed, rhs, blocks, material)
            results.append((rhs, blocks))
    for (rhs, blocks), (rhs_every, blocks_every) in zip(results[:2], results[2:]):
        assert np.all(np.isfinite(rhs)) and np.all(np.isfinite(blocks))
        np.testing.assert_array_equal(rhs, rhs_every)
        np.testing.assert_array_equal(blocks, blocks_every)


@pytest.mark.parametrize('kd', [11, 17])
def test_the_band_link_pass_adds_the_symmetric_part_of_the_exact_blocks(kd):
    """
    link_pass_band_into: the lower band of ``(T + Tᵀ) / 2`` of link_pass's exact blocks ``T``.

    Assembled densely from the blocks (the base frame left out) and compared to rounding (the
    band pass symmetrises before its products); the same wrenches and ``J_aᵀ``, bitwise; the
    trash row of the band untouched.
    """
    rng = np.random.default_rng(17)
    n, c = 4, 3
    links_ = [_random_link(rng) for _ in range(n)]
    stiffness = np.stack([link[0] for link in links_])
    rest_offsets = np.stack([link[1] for link in links_])
    rest_rotations_t = np.ascontiguousarray(np.stack([link[2].T for link in links_]))
    positions = np.cumsum(rng.normal(scale=0.02, size=(n + 1, 3)), axis=0)
    rotations = so3.so3_exp(rng.normal(scale=0.3, size=(n + 1, 3)))
    wrench = rng.normal(size=(n, c, 6))
    hessian = rng.normal(size=(n, c, 6, 6)) * 100.0
    wrench[1, 2] = hessian[1, 2] = 0.0
    # read-only as a scene holds them (the signature of the tick's evaluation)
    stiffness.flags.writeable = rest_offsets.flags.writeable = False
    columns = nonzero_cavity_columns(wrench, hessian)
    actuation = rng.uniform(1e3, 1e5, c)
    size = 6 * n
    rhs = np.zeros((size, c + 1))
    blocks = np.zeros((n, 12, 12))
    link_pass(positions, rotations, stiffness, rest_offsets, rest_rotations_t, actuation, wrench,
              hessian, columns, rhs, blocks, False)
    expected = np.zeros((size + 6, size + 6))
    for link in range(n):
        expected[6 * link:6 * link + 12, 6 * link:6 * link + 12] += blocks[link]
    expected = np.tril(0.5 * (expected + expected.T))[6:, 6:]
    width = kd + 1
    band = np.zeros((size + 1) * width)
    band_rhs = np.full((size, c + 1), np.nan)
    link_pass_band_into(positions, rotations, stiffness, rest_offsets, rest_rotations_t,
                        actuation, wrench, hessian, columns, band_rhs, band,
                        np.zeros(link_work_size(c)))
    got = np.zeros((size, size))
    for col in range(size):
        for offset in range(min(width, size - col)):
            got[col + offset, col] = band[col * width + offset]
    assert np.abs(expected - expected.T).max() > 0.0  # lower triangle only
    assert np.abs(blocks - np.swapaxes(blocks, 1, 2)).max() > 1e-3 * np.abs(blocks).max()
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-14 * np.abs(expected).max())
    np.testing.assert_array_equal(band_rhs, rhs)
    np.testing.assert_array_equal(band[size * width:], 0.0)
