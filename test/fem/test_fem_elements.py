"""Tetrahedral elements, assembly, rigid coupling and SVK kernel against exact properties."""

from cbha_inverse.fem.coupling import build_coupling
from cbha_inverse.fem.elasticity import (assemble_stiffness, mesh_volume, quadrature,
                                         shape_functions)
from cbha_inverse.fem.full_fe import _SvkBody
from cbha_inverse.fem.geometry import gmsh_session, mesh_current_model
from cbha_inverse.fem.mesh import TetMesh
import numpy as np
import pytest
import scipy.sparse.linalg as spla


def _box(order, size=0.5):
    with gmsh_session(size, order, 'box') as gmsh:
        gmsh.model.occ.addBox(0.0, 0.0, 0.0, 1.0, 0.8, 0.6)
        gmsh.model.occ.synchronize()
        return mesh_current_model(gmsh, order)


@pytest.fixture(scope='module')
def boxes():
    """Coarse P1 and P2 meshes of a 1 x 0.8 x 0.6 box (and very coarse ones for eigenvalues)."""
    return {1: _box(1), 2: _box(2), 'eig1': _box(1, 1.0), 'eig2': _box(2, 2.0)}


@pytest.mark.parametrize('order', [1, 2])
def test_shape_functions_partition_of_unity_and_nodal(order):
    xi, w = quadrature(order)
    n, dn = shape_functions(order, xi)
    assert np.allclose(n.sum(axis=1), 1.0)
    assert np.allclose(dn.sum(axis=1), 0.0)
    assert w.sum() == pytest.approx(1.0 / 6.0)
    corners = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    nodes = corners if order == 1 else np.vstack(
        [corners, 0.5 * (corners[[0, 1, 0, 0, 2, 1]] + corners[[1, 2, 2, 3, 3, 3]])])
    n_nodes, _ = shape_functions(order, nodes)
    assert np.allclose(n_nodes, np.eye(len(nodes)))


def test_quadrature_exact_for_degree_two():
    xi, w = quadrature(2)
    # integral of xi^2 over the unit tetrahedron = 1/60, of xi*eta = 1/120
    assert np.dot(w, xi[:, 0] ** 2) == pytest.approx(1.0 / 60.0)
    assert np.dot(w, xi[:, 0] * xi[:, 1]) == pytest.approx(1.0 / 120.0)


@pytest.mark.parametrize('order', [1, 2])
def test_patch_test_uniform_strain_is_exact(boxes, order):
    mesh = boxes[order]
    k = assemble_stiffness(mesh, 2.0e5, 0.3)
    grad = np.array([[1e-3, 2e-4, -3e-4], [5e-4, -2e-3, 1e-4], [0.0, 4e-4, 1.5e-3]])
    exact = (mesh.points @ grad.T + np.array([1e-3, -2e-3, 5e-4])).ravel()
    p = mesh.points
    on_boundary = ((np.abs(p[:, 0]) < 1e-9) | (np.abs(p[:, 0] - 1.0) < 1e-9)
                   | (np.abs(p[:, 1]) < 1e-9) | (np.abs(p[:, 1] - 0.8) < 1e-9)
                   | (np.abs(p[:, 2]) < 1e-9) | (np.abs(p[:, 2] - 0.6) < 1e-9))
    interior_nodes = np.flatnonzero(~on_boundary)
    assert len(interior_nodes) > 0
    inner = (3 * interior_nodes[:, None] + np.arange(3)).ravel()
    outer = np.setdiff1d(np.arange(3 * mesh.n_nodes), inner)
    k = k.tocsr()
    rhs = -k[inner][:, outer] @ exact[outer]
    u_inner = spla.spsolve(k[inner][:, inner].tocsc(), rhs)
    assert np.max(np.abs(u_inner - exact[inner])) < 1e-10 * np.max(np.abs(exact))
    assert mesh_volume(mesh) == pytest.approx(0.48, rel=1e-12)


@pytest.mark.parametrize('order', [1, 2])
def test_free_body_has_exactly_six_zero_energy_modes(boxes, order):
    k = assemble_stiffness(boxes[f'eig{order}'], 1.0, 0.3).toarray()
    assert np.allclose(k, k.T, atol=1e-12 * np.abs(k).max())
    eig = np.linalg.eigvalsh(k)
    scale = eig[-1]
    assert np.all(np.abs(eig[:6]) < 1e-10 * scale)
    assert eig[6] > 1e-6 * scale


def test_rigid_coupling_reproduces_rigid_motion(boxes):
    mesh = boxes[2]
    top = np.flatnonzero(np.abs(mesh.points[:, 0] - 1.0) < 1e-9)
    origin = np.array([1.0, 0.4, 0.3])
    coupling = build_coupling(mesh.points, [top], [origin])
    z = np.zeros(coupling.n_reduced)
    motion = np.array([1e-3, -2e-3, 3e-3, 2e-3, -1e-3, 4e-3])
    z[coupling.frame_dofs(0)] = motion
    u = (coupling.transformation @ z).reshape(-1, 3)
    expected = motion[:3] + np.cross(motion[3:], mesh.points[top] - origin)
    assert np.allclose(u[top], expected, rtol=0, atol=1e-15)
    # a rigid motion of everything has zero energy through the reduced stiffness
    k = assemble_stiffness(mesh, 1.0, 0.3)
    free = coupling.free_nodes
    z[:3 * len(free)] = (motion[:3] + np.cross(motion[3:], mesh.points[free] - origin)).ravel()
    force = coupling.transformation.T @ (k @ (coupling.transformation @ z))
    assert np.max(np.abs(force)) < 1e-12 * abs(k).max()


def test_svk_tangent_matches_finite_differences_and_linear_limit():
    corners = np.array([[0, 0, 0], [1.0, 0.1, 0], [0.2, 0.9, 0], [0.1, 0.2, 1.1]])
    edges = np.array([[0, 1], [1, 2], [0, 2], [0, 3], [2, 3], [1, 3]])
    points = np.vstack([corners, 0.5 * (corners[edges[:, 0]] + corners[edges[:, 1]])])
    mesh = TetMesh(points, np.arange(10)[None])
    body = _SvkBody(mesh, 1.0e3, 0.3)
    rng = np.random.default_rng(0)
    u = 0.05 * rng.standard_normal(body.n_dofs)
    f0, k_t = body.evaluate(u)
    k_t = k_t.toarray()
    eps = 1e-6
    fd = np.empty_like(k_t)
    for j in range(body.n_dofs):
        du = np.zeros(body.n_dofs)
        du[j] = eps
        fd[:, j] = (body.evaluate(u + du, False)[0] - body.evaluate(u - du, False)[0]) / (2 * eps)
    assert np.allclose(k_t, fd, atol=1e-6 * np.abs(k_t).max())
    _, k_zero = body.evaluate(np.zeros(body.n_dofs))
    k_lin = assemble_stiffness(mesh, 1.0e3, 0.3).toarray()
    assert np.allclose(k_zero.toarray(), k_lin, atol=1e-12 * np.abs(k_lin).max())
