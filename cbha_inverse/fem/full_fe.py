"""
Full-FE reference of a multi-segment body with rigid vertebrae ("the classical FEM model").

The body is one tetrahedral mesh of n stacked segments along +x; the nodes on the plane x = 0
are clamped and the nodes on each interface plane x = i L (i = 1..n) follow a rigid vertebra
frame i. Linear elasticity gives the tip compliance; the geometrically nonlinear model is total
Lagrangian St Venant-Kirchhoff with the rigid constraints enforced exactly for finite rotations
(u_k = d_f + (R_f - I) r_k), solved by Newton with load stepping.
"""

from dataclasses import dataclass
import time

from cbha_inverse.core.so3 import hat, so3_exp
from cbha_inverse.fem.condensation import frame_compliance
from cbha_inverse.fem.coupling import build_coupling, coupling_matrix, RigidCoupling
from cbha_inverse.fem.elasticity import (assemble_blocks, assemble_stiffness, element_dofs,
                                         lame_parameters, shape_gradients)
from cbha_inverse.fem.mesh import nodes_on_plane
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


def stacked_coupling(mesh, n_segments, length):
    """
    Return the rigid coupling of a stacked body: clamp x = 0, frame i on the plane x = i L.

    Parameters
    ----------
    mesh : TetMesh
        Mesh of the whole body, conforming on the interface planes.
    n_segments : int
        Number of segments n.
    length : float  [m]
        Segment length L.

    Returns
    -------
    RigidCoupling
        Frames 1..n (index 0..n-1), origins (i L, 0, 0).

    """
    sets = [nodes_on_plane(mesh, i * length) for i in range(1, n_segments + 1)]
    origins = [[i * length, 0.0, 0.0] for i in range(1, n_segments + 1)]
    return build_coupling(mesh.points, sets, origins, nodes_on_plane(mesh, 0.0))


def linear_tip_compliance(mesh, youngs_modulus, poisson_ratio, n_segments, length):
    """
    Return the linear 6x6 compliance of the last vertebra frame of a stacked body.

    Parameters
    ----------
    mesh : TetMesh
        Body mesh.
    youngs_modulus : float  [Pa]
        Young's modulus.
    poisson_ratio : float
        Poisson's ratio.
    n_segments : int
        Number of segments.
    length : float  [m]
        Segment length.

    Returns
    -------
    compliance : (6, 6) ndarray
        Tip compliance in base axes (frame 0 clamped).
    timings : dict
        Seconds for 'assembly', 'reduce', 'factor', 'solve'.

    """
    t0 = time.perf_counter()
    coupling = stacked_coupling(mesh, n_segments, length)
    stiffness = assemble_stiffness(mesh, youngs_modulus, poisson_ratio)
    t1 = time.perf_counter()
    compliance, timings = frame_compliance(stiffness, coupling, frame=-1)
    return compliance, {'assembly': t1 - t0, **timings}


@dataclass(frozen=True)
class NonlinearResult:
    """
    Result of :func:`solve_nonlinear`.

    Attributes
    ----------
    positions : (n + 1, 3) ndarray  [m]
        Vertebra frame origins, frame 0 = base.
    rotations : (n + 1, 3, 3) ndarray
        Vertebra frame rotations.
    converged : bool
        Full load reached with the residual below tolerance.
    iterations : int
        Total Newton iterations.
    load_steps : int
        Successful load steps.
    residual_norm : float  [N]
        Final max-norm of the reduced residual.
    seconds : float  [s]
        Wall-clock time of the solve (assembly, factorisations, updates).
    message : str
        What happened.

    """

    positions: np.ndarray
    rotations: np.ndarray
    converged: bool
    iterations: int
    load_steps: int
    residual_norm: float
    seconds: float
    message: str


def svk_element_terms(grads, weights, u_el, lam, mu, tangent=True):
    """
    Return St Venant-Kirchhoff element forces and tangents (total Lagrangian).

    F = I + grad u, E = (F^T F - I) / 2, S = lam tr(E) I + 2 mu E, P = F S;
    f_a = sum_q w P g_a and K_ab,ik = sum_q w [lam (F g_a)_i (F g_b)_k + mu (F F^T)_ik g_a.g_b
    + mu (F g_b)_i (F g_a)_k + delta_ik g_a.S g_b].

    Parameters
    ----------
    grads : (E, Q, A, 3) ndarray
        Reference shape-function gradients.
    weights : (E, Q) ndarray
        Quadrature weights times reference det J.
    u_el : (E, A, 3) ndarray  [m]
        Element nodal displacements.
    lam, mu : float  [Pa]
        Lamé parameters.
    tangent : bool
        Also return the tangent blocks.

    Returns
    -------
    forces : (E, 3A) ndarray  [N]
        Internal nodal forces.
    blocks : (E, 3A, 3A) ndarray or None  [N/m]
        Tangent stiffness blocks.

    """
    n_el, n_q, n_a, _ = grads.shape
    eye = np.eye(3)
    forces = np.zeros((n_el, n_a, 3))
    blocks = np.zeros((n_el, n_a, 3, n_a, 3)) if tangent else None
    for q in range(n_q):
        g = grads[:, q]
        w = weights[:, q]
        f_def = eye + np.einsum('eai,eaj->eij', u_el, g)
        green = 0.5 * (np.einsum('eki,ekj->eij', f_def, f_def) - eye)
        stress = lam * np.trace(green, axis1=1, axis2=2)[:, None, None] * eye + 2.0 * mu * green
        first = np.einsum('eij,ejk->eik', f_def, stress)
        forces += w[:, None, None] * np.einsum('eij,eaj->eai', first, g)
        if tangent:
            fg = np.einsum('eij,eaj->eai', f_def, g)
            b_left = np.einsum('eij,ekj->eik', f_def, f_def)
            gg = np.einsum('eaj,ebj->eab', g, g)
            gsg = np.einsum('eaj,ejk,ebk->eab', g, stress, g)
            ww = w[:, None, None, None, None]
            blocks += ww * lam * np.einsum('eai,ebk->eaibk', fg, fg)
            blocks += ww * mu * np.einsum('eik,eab->eaibk', b_left, gg)
            blocks += ww * mu * np.einsum('ebi,eak->eaibk', fg, fg)
            blocks += ww * np.einsum('eab,ik->eaibk', gsg, eye)
    forces = forces.reshape(n_el, 3 * n_a)
    if tangent:
        blocks = blocks.reshape(n_el, 3 * n_a, 3 * n_a)
    return forces, blocks


class _SvkBody:
    """Precomputed reference data of a body for repeated SVK evaluations."""

    def __init__(self, mesh, youngs_modulus, poisson_ratio):
        self.mesh = mesh
        self.grads, self.weights = shape_gradients(mesh)
        self.lam, self.mu = (float(v) for v in lame_parameters(youngs_modulus, poisson_ratio))
        self.dofs = element_dofs(mesh.tets)
        self.n_dofs = 3 * mesh.n_nodes

    def evaluate(self, u, tangent=True):
        u_el = u.reshape(-1, 3)[self.mesh.tets]
        forces, blocks = svk_element_terms(self.grads, self.weights, u_el, self.lam, self.mu,
                                           tangent)
        f_int = np.bincount(self.dofs.ravel(), forces.ravel(), minlength=self.n_dofs)
        k_t = assemble_blocks(blocks, self.dofs, self.n_dofs) if tangent else None
        return f_int, k_t


def _frame_geometric_blocks(coupling, f_int, arms):
    """Return sum_k hat(f_k) hat(a_k) per frame: the constraint's geometric stiffness."""
    f_nodes = f_int.reshape(-1, 3)
    return [np.einsum('kij,kjl->il', hat(f_nodes[nodes]), hat(arm))
            for nodes, arm in zip(coupling.frame_nodes, arms)]


def solve_nonlinear(mesh, youngs_modulus, poisson_ratio, n_segments, length, tip_wrench, *,
                    load_steps=4, tolerance=1e-8, max_iterations=25, max_attempts=40):
    """
    Solve the St Venant-Kirchhoff body under a dead wrench at its last vertebra frame.

    Parameters
    ----------
    mesh : TetMesh
        Body mesh (x from 0 to n L, conforming interface planes).
    youngs_modulus : float  [Pa]
        Young's modulus.
    poisson_ratio : float
        Poisson's ratio.
    n_segments : int
        Number of segments (vertebra frames 1..n).
    length : float  [m]
        Segment length.
    tip_wrench : (6,) array_like  [N, N*m]
        Dead wrench at the last frame origin, world axes.
    load_steps : int
        Initial number of equal load increments (halved on failure, grown on success).
    tolerance : float
        Convergence when max |residual| (moments / body length) <= tolerance * max |load|.
    max_iterations : int
        Newton iterations per load step.
    max_attempts : int
        Load-step attempts allowed.

    Returns
    -------
    NonlinearResult
        Frame poses; ``converged`` False with a message if the full load was not reached.

    """
    t_start = time.perf_counter()
    body = _SvkBody(mesh, youngs_modulus, poisson_ratio)
    base = stacked_coupling(mesh, n_segments, length)
    ref = mesh.points
    origins0 = base.frame_origins.copy()
    arms0 = [ref[nodes] - origins0[j] for j, nodes in enumerate(base.frame_nodes)]
    free_dofs = (3 * base.free_nodes[:, None] + np.arange(3)).ravel()
    n_free = len(free_dofs)
    total_length = n_segments * length
    wrench = np.asarray(tip_wrench, dtype=float)
    f_ext = np.zeros(base.n_reduced)
    f_ext[base.frame_dofs(-1)] = wrench
    scale = np.ones(base.n_reduced)
    for j in range(n_segments):
        scale[base.frame_dofs(j)[3:]] = 1.0 / total_length
    load_scale = np.max(np.abs(f_ext * scale))

    def assemble(state):
        u_free, disp, rots = state
        u = np.zeros(body.n_dofs)
        u[free_dofs] = u_free
        arms = [np.einsum('ij,kj->ki', rots[j], arms0[j]) for j in range(n_segments)]
        for j, nodes in enumerate(base.frame_nodes):
            u.reshape(-1, 3)[nodes] = disp[j] + arms[j] - arms0[j]
        return u, arms

    def residual(state, lam, tangent):
        u, arms = assemble(state)
        f_int, k_t = body.evaluate(u, tangent)
        current = RigidCoupling(None, base.free_nodes, origins0 + state[1], base.frame_nodes)
        t_mat = coupling_matrix(current, ref + u.reshape(-1, 3)).transformation
        r = t_mat.T @ f_int - lam * f_ext
        if not tangent:
            return r, None
        blocks = np.array(_frame_geometric_blocks(base, f_int, arms))
        idx = np.array([base.frame_dofs(j)[3:] for j in range(n_segments)])
        geometric = sp.coo_matrix(
            (blocks.ravel(), (np.repeat(idx, 3, axis=1).ravel(), np.tile(idx, 3).ravel())),
            shape=(base.n_reduced, base.n_reduced))
        return r, (t_mat.T @ k_t @ t_mat + geometric).tocsc()

    def update(state, dz):
        u_free, disp, rots = state
        frames = dz[n_free:].reshape(n_segments, 6)
        return (u_free + dz[:n_free], disp + frames[:, :3],
                np.einsum('fij,fjk->fik', so3_exp(frames[:, 3:]), rots))

    state = (np.zeros(n_free), np.zeros((n_segments, 3)), np.tile(np.eye(3), (n_segments, 1, 1)))
    lam, step, total_iter, done_steps, attempts = 0.0, 1.0 / load_steps, 0, 0, 0
    r_norm, message = np.inf, ''
    while lam < 1.0 and attempts < max_attempts:
        attempts += 1
        target = min(1.0, lam + step)
        trial = state
        ok = False
        for _ in range(max_iterations):
            r, k_red = residual(trial, target, True)
            r_norm = float(np.max(np.abs(r * scale)))
            if not np.isfinite(r_norm):
                break
            if r_norm <= tolerance * load_scale:
                ok = True
                break
            total_iter += 1
            dz = -spla.splu(k_red, permc_spec='MMD_AT_PLUS_A').solve(r)
            trial = update(trial, dz)
        if ok:
            state, lam, done_steps = trial, target, done_steps + 1
            step = min(2.0 * step, 1.0 - lam) if lam < 1.0 else step
        else:
            step *= 0.5
    converged = lam >= 1.0
    message = ('converged' if converged else
               f'stopped at load factor {lam:.4f} after {attempts} attempts')
    positions = np.vstack([np.zeros(3), origins0 + state[1]])
    rotations = np.concatenate([np.eye(3)[None], state[2]])
    return NonlinearResult(positions, rotations, converged, total_iter, done_steps, r_norm,
                           time.perf_counter() - t_start, message)
