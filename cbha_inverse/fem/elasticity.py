"""
Isoparametric P1 / P2 tetrahedra: shape functions, quadrature and vectorised linear elasticity.

Every element quantity is computed for all elements at once with ``numpy.einsum`` (one short
Python loop over the few quadrature points, none over elements) and assembled in one
``scipy.sparse.coo_matrix`` per chunk of elements.
"""

import numpy as np
import scipy.sparse as sp

#: Reference-tetrahedron volume.
_REFERENCE_VOLUME = 1.0 / 6.0

#: Mid-edge node k (4..9) of a 10-node tetrahedron sits on the edge between these vertices (gmsh).
P2_EDGES = np.array([[0, 1], [1, 2], [0, 2], [0, 3], [2, 3], [1, 3]])

#: Gradients of the barycentric coordinates (L0, L1, L2, L3) with respect to (xi, eta, zeta).
_DL = np.array([[-1.0, -1.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])

#: Elements per assembly chunk (bounds peak memory of the dense element blocks).
CHUNK = 8000


def quadrature(order):
    """
    Return a tetrahedron quadrature rule exact for polynomials of degree ``2 * (order - 1)``.

    Parameters
    ----------
    order : {1, 2}
        Element order: 1 gives the 1-point centroid rule, 2 the 4-point degree-2 rule.

    Returns
    -------
    points : (Q, 3) ndarray
        Reference coordinates (xi, eta, zeta).
    weights : (Q,) ndarray
        Weights summing to the reference volume 1/6.

    """
    if order == 1:
        return np.full((1, 3), 0.25), np.array([_REFERENCE_VOLUME])
    if order == 2:
        a, b = 0.5854101966249685, 0.1381966011250105
        bary = np.full((4, 4), b) + np.eye(4) * (a - b)
        return bary[:, 1:], np.full(4, _REFERENCE_VOLUME / 4.0)
    raise ValueError(f'element order must be 1 or 2, got {order}')


def shape_functions(order, xi):
    """
    Evaluate the shape functions and their reference gradients.

    Parameters
    ----------
    order : {1, 2}
        Element order (4 or 10 nodes, gmsh order).
    xi : (Q, 3) ndarray
        Reference coordinates.

    Returns
    -------
    n : (Q, A) ndarray
        Shape function values, A = 4 or 10.
    dn : (Q, A, 3) ndarray
        Gradients with respect to (xi, eta, zeta).

    """
    xi = np.atleast_2d(np.asarray(xi, dtype=float))
    bary = np.column_stack([1.0 - xi.sum(axis=1), xi])
    n_q = len(xi)
    if order == 1:
        return bary, np.broadcast_to(_DL, (n_q, 4, 3)).copy()
    if order != 2:
        raise ValueError(f'element order must be 1 or 2, got {order}')
    n = np.empty((n_q, 10))
    dn = np.empty((n_q, 10, 3))
    n[:, :4] = bary * (2.0 * bary - 1.0)
    dn[:, :4] = (4.0 * bary - 1.0)[:, :, None] * _DL[None]
    ea, eb = P2_EDGES[:, 0], P2_EDGES[:, 1]
    n[:, 4:] = 4.0 * bary[:, ea] * bary[:, eb]
    dn[:, 4:] = 4.0 * (bary[:, ea, None] * _DL[None, eb] + bary[:, eb, None] * _DL[None, ea])
    return n, dn


def lame_parameters(youngs_modulus, poisson_ratio):
    """
    Return the Lamé parameters (lambda, mu) of an isotropic material.

    Parameters
    ----------
    youngs_modulus : float or ndarray  [Pa]
        Young's modulus E.
    poisson_ratio : float or ndarray
        Poisson's ratio nu, -1 < nu < 0.5.

    Returns
    -------
    lam, mu : float or ndarray  [Pa]
        lambda = E nu / ((1 + nu)(1 - 2 nu)), mu = E / (2 (1 + nu)).

    """
    e_mod = np.asarray(youngs_modulus, dtype=float)
    nu = np.asarray(poisson_ratio, dtype=float)
    if not (np.all(np.isfinite(e_mod)) and np.all(np.isfinite(nu))):
        raise ValueError('youngs_modulus and poisson_ratio must be finite')
    if np.any(e_mod <= 0) or np.any(nu <= -1.0) or np.any(nu >= 0.5):
        raise ValueError('need E > 0 and -1 < nu < 0.5')
    return e_mod * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), e_mod / (2.0 * (1.0 + nu))


def shape_gradients(mesh):
    """
    Return the physical shape-function gradients and integration weights at quadrature points.

    The geometry is isoparametric (curved P2 edges are honoured).

    Parameters
    ----------
    mesh : TetMesh
        Order 1 or 2 mesh.

    Returns
    -------
    grads : (E, Q, A, 3) ndarray  [1/m]
        d N_a / d x at each quadrature point of each element.
    weights : (E, Q) ndarray  [m^3]
        Quadrature weight times Jacobian determinant.

    Raises
    ------
    ValueError
        If an element has a non-positive Jacobian (inverted or degenerate element).

    """
    xi, w = quadrature(mesh.order)
    _, dn = shape_functions(mesh.order, xi)
    x_el = mesh.points[mesh.tets]
    jac = np.einsum('eai,qaj->eqij', x_el, dn)
    det = np.linalg.det(jac)
    if np.any(det <= 0.0):
        bad = int(np.count_nonzero(det <= 0.0))
        raise ValueError(f'{bad} quadrature points with non-positive Jacobian (inverted elements)')
    inv = np.linalg.inv(jac)
    grads = np.einsum('qaj,eqji->eqai', dn, inv)
    return grads, det * w[None, :]


def element_dofs(tets):
    """
    Return the global dof indices (E, 3A) of the elements, node-major (3 k + component).

    Parameters
    ----------
    tets : (E, A) int ndarray
        Connectivity.

    Returns
    -------
    (E, 3A) int ndarray
        Dof indices.

    """
    return (3 * tets[:, :, None] + np.arange(3)[None, None, :]).reshape(len(tets), -1)


def linear_element_stiffness(grads, weights, lam, mu):
    """
    Return the linear-elastic element stiffness blocks.

    K_e[a i, b k] = sum_q w_q (lam g_ai g_bk + mu g_ak g_bi + mu delta_ik g_a . g_b).

    Parameters
    ----------
    grads : (E, Q, A, 3) ndarray
        Physical shape-function gradients.
    weights : (E, Q) ndarray
        Quadrature weights times det J.
    lam, mu : float or (E,) ndarray  [Pa]
        Lamé parameters.

    Returns
    -------
    (E, 3A, 3A) ndarray
        Element stiffness matrices.

    """
    n_el, n_q, n_a, _ = grads.shape
    lam = np.broadcast_to(np.asarray(lam, dtype=float), (n_el,))
    mu = np.broadcast_to(np.asarray(mu, dtype=float), (n_el,))
    k_e = np.zeros((n_el, n_a, 3, n_a, 3))
    eye = np.eye(3)
    for q in range(n_q):
        g = grads[:, q]
        wl = (weights[:, q] * lam)[:, None, None, None, None]
        wm = (weights[:, q] * mu)[:, None, None, None, None]
        k_e += wl * np.einsum('eai,ebk->eaibk', g, g)
        k_e += wm * np.einsum('eak,ebi->eaibk', g, g)
        gg = np.einsum('eaj,ebj->eab', g, g)
        k_e += wm * np.einsum('eab,ik->eaibk', gg, eye)
    return k_e.reshape(n_el, 3 * n_a, 3 * n_a)


def assemble_blocks(blocks, dofs, n_dofs):
    """
    Assemble element blocks into a sparse CSR matrix (duplicates summed).

    Parameters
    ----------
    blocks : (E, D, D) ndarray
        Element matrices.
    dofs : (E, D) int ndarray
        Global dof indices of each element.
    n_dofs : int
        Global size.

    Returns
    -------
    scipy.sparse.csr_matrix
        (n_dofs, n_dofs) matrix.

    """
    d = dofs.shape[1]
    rows = np.repeat(dofs, d, axis=1).ravel()
    cols = np.tile(dofs, (1, d)).ravel()
    return sp.coo_matrix((blocks.ravel(), (rows, cols)), shape=(n_dofs, n_dofs)).tocsr()


def assemble_stiffness(mesh, youngs_modulus, poisson_ratio):
    """
    Assemble the global linear-elastic stiffness matrix of a tetrahedral mesh.

    Parameters
    ----------
    mesh : TetMesh
        Order 1 or 2 mesh.
    youngs_modulus : float or (E,) ndarray  [Pa]
        Young's modulus (per element allowed).
    poisson_ratio : float or (E,) ndarray
        Poisson's ratio.

    Returns
    -------
    scipy.sparse.csr_matrix
        (3N, 3N) stiffness, dof 3 k + i is component i of node k  [N/m].

    """
    lam, mu = lame_parameters(youngs_modulus, poisson_ratio)
    lam = np.broadcast_to(lam, (mesh.n_elements,))
    mu = np.broadcast_to(mu, (mesh.n_elements,))
    n_dofs = 3 * mesh.n_nodes
    total = sp.csr_matrix((n_dofs, n_dofs))
    for start in range(0, mesh.n_elements, CHUNK):
        sl = slice(start, start + CHUNK)
        sub = type(mesh)(mesh.points, mesh.tets[sl])
        grads, weights = shape_gradients(sub)
        blocks = linear_element_stiffness(grads, weights, lam[sl], mu[sl])
        total = total + assemble_blocks(blocks, element_dofs(sub.tets), n_dofs)
    return total.tocsr()


def mesh_volume(mesh):
    """
    Return the (isoparametric) volume of the mesh.

    Parameters
    ----------
    mesh : TetMesh
        The mesh.

    Returns
    -------
    float  [m^3]
        Sum over elements of the quadrature of det J.

    """
    _, weights = shape_gradients(mesh)
    return float(weights.sum())
