"""
The chain's link forces, tangents and assembly in batched numpy (oracle of the link kernels).

The readable reference of :func:`cbha_inverse.core._kernels.links.link_pass` (what the control
tick, the static solver and the plant run), vectorised over the links with numpy.
A link joins frame a (= frame i) to frame b (= frame i+1). Its data are a symmetric positive
definite 6x6 stiffness ``K = C^-1`` (C as the paper defines it: frame a clamped, loads at the
origin of frame b, all in frame-a axes; paper eq. 2-4) and the rest transform of frame
b seen from frame a (offset ``d0``, rotation ``Q0``).

Local deformation (paper eq. 4-8)::

    delta = [ R_a^T (x_b - x_a) - d0 ;  log(R_a^T R_b Q0^T) ]          (frame-a axes)

The link stores the energy ``U = delta^T K delta / 2``; its wrenches are the exact generalised
forces ``-dU/dq`` for world-axis increments (dx, dtheta) with ``R <- exp(dtheta) R``:

- on frame b, in frame-a axes at the origin of b: force ``-(K delta)_t`` (exactly the linear
  ``w = -K delta``) and moment ``-Jl^-1(phi)^T (K delta)_r``, where ``Jl^-1`` is the inverse left
  Jacobian of SO(3) at ``phi = delta_r``. The factor ``Jl^-1^T = I + O(|phi|)`` makes the link
  conservative (symmetric material tangent, rigid-body invariance, equilibrium) and does not change
  the linear response at rest, which is the paper's eq. 4-8;
- on frame a: the opposite force and the opposite moment transported from x_b to x_a
  (the paper's H matrix, eq. 5-6).
Both are rotated to world axes with R_a (paper eq. 7).

The 12x12 tangent ``T = -d[w_a; w_b]/d[dq_a; dq_b]`` is the exact derivative: material part
``B^T K B`` (paper eq. 8 with the rotation made explicit) plus the geometric (load-dependent) part.
Its off-diagonal 6x6 blocks satisfy ``T_ba = T_ab^T``; the rotational 3x3 part of each diagonal
block carries an antisymmetric part ``hat(m)/2`` (m: the link moment on that frame), the
well-known non-symmetry of spatial rotation increments away from equilibrium.

Assembly: frames 1..n move (frame 0 is the fixed base). Link i joins frame i to frame i+1, so
frame j (1-based) receives the b-side wrench of link j-1 and the a-side wrench of link j; the
global tangent is block tridiagonal with 6x6 blocks (paper Sec. III, Fig. 1).
"""

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from oracles.so3 import (_jl_inv_coefficient, _jl_inv_from_hat, hat,
                         so3_left_jacobian_inverse_transpose_derivative, so3_log, so3_log_angle)


_EYE4 = np.eye(4)
# constant entries of the local deformation Jacobian B (see local_tangent)
_B_TEMPLATE = np.zeros((6, 12))
_B_TEMPLATE[:3, :3] = -np.eye(3)
_B_TEMPLATE[:3, 6:9] = np.eye(3)


class LinkTerms(NamedTuple):
    """Local (frame-a axes) quantities of a batch of links shared by wrench and tangent."""

    offset: np.ndarray          # (..., 3) R_a^T (x_b - x_a)
    phi: np.ndarray             # (..., 3) log(R_a^T R_b Q0^T)
    phi_hat: np.ndarray         # (..., 3, 3) hat(phi)
    coefficients: tuple         # (c, c'/t) of Jl^-1 at |phi|
    jinv: np.ndarray            # (..., 3, 3) Jl^-1(phi)
    stress: np.ndarray          # (..., 6) K delta
    wrench_b: np.ndarray        # (..., 6) wrench on frame b, frame-a axes, at x_b


def _float_arrays(*values):
    """Return the values as float ndarrays (public entry points take array_like)."""
    return [np.asarray(v, dtype=float) for v in values]


def _relative_pose(rest_rotation, position_a, rotation_a, position_b, rotation_b):
    """Offset ``R_a^T (x_b - x_a)`` and rotation ``R_a^T R_b Q0^T`` (``Q0`` None: identity)."""
    rot_at = np.swapaxes(rotation_a, -1, -2)
    offset = (rot_at @ (position_b - position_a)[..., None])[..., 0]
    rel = rot_at @ rotation_b
    if rest_rotation is not None:
        rel = rel @ np.swapaxes(rest_rotation, -1, -2)
    return offset, rel


def link_deformation(rest_offset, rest_rotation, position_a, rotation_a, position_b, rotation_b):
    """
    Local deformation ``delta`` of links (paper eq. 4-8), frame-a axes.

    Parameters
    ----------
    rest_offset, rest_rotation, position_a, rotation_a, position_b, rotation_b : array_like
        Rest transform and frame poses, as in :func:`link_wrenches`.

    Returns
    -------
    (..., 6) ndarray  [m, rad]
        ``[R_a^T (x_b - x_a) - d0; log(R_a^T R_b Q0^T)]``.

    """
    offset, rel = _relative_pose(*_float_arrays(rest_rotation, position_a, rotation_a,
                                                position_b, rotation_b))
    return np.concatenate([offset - rest_offset, so3_log(rel)], axis=-1)


def link_terms(stiffness, rest_offset, rest_rotation, position_a, rotation_a, position_b,
               rotation_b):
    """
    Evaluate the local quantities of a batch of links (see :class:`LinkTerms`).

    Parameters
    ----------
    stiffness : (..., 6, 6) array_like  [N/m, N, N*m/rad]
        Link stiffness K = C^-1 (frame-a axes).
    rest_offset : (..., 3) array_like  [m]
        Origin of frame b in frame-a axes at rest (d0).
    rest_rotation : (..., 3, 3) ndarray or None
        Rotation of frame b in frame a at rest (Q0); None for identity.
    position_a : (..., 3) ndarray  [m]
        World position of frame a.
    rotation_a : (..., 3, 3) ndarray
        World rotation of frame a.
    position_b : (..., 3) ndarray  [m]
        World position of frame b.
    rotation_b : (..., 3, 3) ndarray
        World rotation of frame b.

    Returns
    -------
    LinkTerms

    """
    offset, rel = _relative_pose(rest_rotation, position_a, rotation_a, position_b, rotation_b)
    phi, theta = so3_log_angle(rel)
    delta = np.concatenate([offset - rest_offset, phi], axis=-1)
    stress = (stiffness @ delta[..., None])[..., 0]
    coefficients = _jl_inv_coefficient(theta)
    phi_hat = hat(phi)
    jinv = _jl_inv_from_hat(phi_hat, coefficients[0])
    wrench_b = np.empty_like(stress)
    wrench_b[..., :3] = -stress[..., :3]
    wrench_b[..., 3:] = -(stress[..., None, 3:] @ jinv)[..., 0, :]
    return LinkTerms(offset, phi, phi_hat, coefficients, jinv, stress, wrench_b)


def wrench_pair_from_terms(terms, rotation_a):
    """
    World wrenches on frames a and b from local link terms (paper eq. 5-7).

    Parameters
    ----------
    terms : LinkTerms
        Local link quantities from :func:`link_terms`.
    rotation_a : (..., 3, 3) ndarray
        World rotation of frame a.

    Returns
    -------
    wrench_a, wrench_b : (..., 6) ndarrays  [N, N*m]
        Each at its own frame origin, world axes.

    """
    w_b = terms.wrench_b
    f_b = w_b[..., :3]
    lever = (hat(terms.offset) @ f_b[..., None])[..., 0]
    # columns: force on a, moment on a, force on b, moment on b (local), then one rotation
    local = np.stack([-f_b, -w_b[..., 3:] - lever, f_b, w_b[..., 3:]], axis=-1)
    world = np.swapaxes(rotation_a @ local, -1, -2)
    shape = world.shape[:-2] + (6,)
    return world[..., :2, :].reshape(shape), world[..., 2:, :].reshape(shape)


def link_wrenches(stiffness, rest_offset, rest_rotation, position_a, rotation_a, position_b,
                  rotation_b):
    """
    World wrenches that a batch of compliance links applies to its two frames.

    Parameters
    ----------
    stiffness : (..., 6, 6) array_like  [N/m, N, N*m/rad]
        Link stiffness K = C^-1 (frame-a axes).
    rest_offset : (..., 3) array_like  [m]
        Origin of frame b in frame-a axes at rest (d0).
    rest_rotation : (..., 3, 3) array_like
        Rotation of frame b in frame a at rest (Q0).
    position_a : (..., 3) array_like  [m]
        World position of frame a.
    rotation_a : (..., 3, 3) array_like
        World rotation of frame a.
    position_b : (..., 3) array_like  [m]
        World position of frame b.
    rotation_b : (..., 3, 3) array_like
        World rotation of frame b.

    Returns
    -------
    wrench_a, wrench_b : (..., 6) ndarrays  [N, N*m]
        On frame a at x_a and on frame b at x_b, world axes.

    """
    args = _float_arrays(stiffness, rest_offset, rest_rotation, position_a, rotation_a,
                         position_b, rotation_b)
    terms = link_terms(*args)
    return wrench_pair_from_terms(terms, args[4])


def local_material_tangent(terms, stiffness):
    """
    Material part ``B^T K B`` of the 12x12 link tangent in frame-a axes (paper eq. 8).

    ``B`` is the local deformation Jacobian of :func:`local_tangent`; without the geometric
    (stress) part the result is symmetric positive semi-definite whatever the loads.

    Parameters
    ----------
    terms : LinkTerms
        Local link quantities from :func:`link_terms`.
    stiffness : (..., 6, 6) ndarray
        Link stiffness K.

    Returns
    -------
    (..., 12, 12) ndarray
        Rows and columns ordered (frame a, frame b).

    """
    bmat = np.broadcast_to(_B_TEMPLATE, terms.phi.shape[:-1] + (6, 12)).copy()
    bmat[..., :3, 3:6] = hat(terms.offset)
    bmat[..., 3:, 9:] = terms.jinv
    bmat[..., 3:, 3:6] = -terms.jinv
    return np.swapaxes(bmat, -1, -2) @ (stiffness @ bmat)


def local_tangent(terms, stiffness):
    """
    Exact 12x12 link tangent in frame-a axes, rows and columns ordered (frame a, frame b).

    Material part ``B^T K B`` with the local deformation Jacobian (world increments rotated to
    frame-a axes)::

        B = [ -I   hat(p)   I   0  ]      p: current offset of b from a (the paper's H matrix)
            [  0   -Jl^-1   0  Jl^-1 ]

    plus the geometric part from the rotation of the force with R_a (``hat(s_t)``), the moving
    lever arm and the variation of ``Jl^-1`` (``DJ = d(Jl^-T s_r)/dphi Jl^-1``).

    Parameters
    ----------
    terms : LinkTerms
        Local link quantities from :func:`link_terms`.
    stiffness : (..., 6, 6) ndarray
        Link stiffness K.

    Returns
    -------
    (..., 12, 12) ndarray

    """
    jinv = terms.jinv
    p_hat = hat(terms.offset)
    out = local_material_tangent(terms, stiffness)
    f_hat = hat(terms.stress[..., :3])
    m_hat = hat(terms.wrench_b[..., 3:])
    dj = so3_left_jacobian_inverse_transpose_derivative(
        terms.phi, terms.stress[..., 3:], terms.coefficients) @ jinv
    out[..., 0:3, 3:6] += f_hat
    out[..., 3:6, 0:3] -= f_hat
    out[..., 3:6, 3:6] += p_hat @ f_hat - m_hat + dj
    out[..., 3:6, 6:9] += f_hat
    out[..., 6:9, 3:6] -= f_hat
    out[..., 3:6, 9:12] -= dj
    out[..., 9:12, 3:6] += m_hat - dj
    out[..., 9:12, 9:12] += dj
    return out


def rotate_tangent(rotation_a, tangent):
    """
    Rotate 12x12 link tangents from frame-a axes to world axes: ``R4 T R4^T``.

    Parameters
    ----------
    rotation_a : (..., 3, 3) ndarray
        World rotation of frame a.
    tangent : (..., 12, 12) ndarray
        Tangents in frame-a axes.

    Returns
    -------
    (..., 12, 12) ndarray

    """
    batch = rotation_a.shape[:-2]
    r4 = (_EYE4[:, None, :, None] * rotation_a[..., None, :, None, :]).reshape(batch + (12, 12))
    return r4 @ tangent @ np.swapaxes(r4, -1, -2)


def link_tangent(stiffness, rest_offset, rest_rotation, position_a, rotation_a, position_b,
                 rotation_b):
    """
    Exact 12x12 tangent of a batch of links, ``T = -d[w_a; w_b] / d[dq_a; dq_b]`` (world axes).

    The increments are world-axis ``dq = (dx, dy, dz, rx, ry, rz)`` applied as
    ``x <- x + dx``, ``R <- exp(dtheta) R`` (see :func:`cbha_inverse.core.chain.retract`).

    Parameters
    ----------
    stiffness, rest_offset, rest_rotation, position_a, rotation_a, position_b, rotation_b
        Link data and frame poses, as in :func:`link_wrenches`.

    Returns
    -------
    (..., 12, 12) ndarray
        Rows and columns ordered (frame a, frame b).

    """
    args = _float_arrays(stiffness, rest_offset, rest_rotation, position_a, rotation_a,
                         position_b, rotation_b)
    terms = link_terms(*args)
    return rotate_tangent(args[4], local_tangent(terms, args[0]))


@dataclass(frozen=True, eq=False)
class TangentSystem:
    """
    Internal wrenches and symmetric block-tridiagonal tangent of a chain at one state.

    Attributes
    ----------
    internal : (n, 6) ndarray  [N, N*m]
        Total link wrench on frames 1..n, world axes, at each frame origin (paper eq. 9, f(q)).
    diagonal : (n, 6, 6) ndarray
        Symmetric diagonal blocks of ``K = -d internal / d increments`` (world-axis increments).
    upper : (n - 1, 6, 6) ndarray
        ``upper[i]`` = block (i, i+1) of frames 1..n; block (i+1, i) is its transpose (exact).

    Notes
    -----
    The exact derivative differs from the symmetric tangent only by the antisymmetric part
    ``hat(m_j) / 2`` of the rotational 3x3 part of diagonal block j, ``m_j`` the internal moment
    on frame j (see :attr:`exact_diagonal`). It vanishes at an equilibrium without applied
    moments, so Newton with the symmetric tangent stays quadratic there.

    """

    internal: np.ndarray
    diagonal: np.ndarray
    upper: np.ndarray

    @property
    def exact_diagonal(self):
        """Return the exact (non-symmetric) diagonal blocks, (n, 6, 6)."""
        out = self.diagonal.copy()
        out[:, 3:, 3:] += 0.5 * hat(self.internal[:, 3:])
        return out

    def to_dense(self, exact=False):
        """
        Return the tangent as a dense (6n, 6n) matrix (for tests and small problems).

        Parameters
        ----------
        exact : bool
            Use :attr:`exact_diagonal` instead of the symmetric diagonal blocks.

        Returns
        -------
        (6n, 6n) ndarray

        """
        return blocks_to_dense(self.exact_diagonal if exact else self.diagonal, self.upper)


def blocks_to_dense(diagonal, upper, lower=None):
    """
    Build a dense matrix from block-tridiagonal storage.

    Parameters
    ----------
    diagonal : (n, 6, 6) array_like
        Diagonal blocks.
    upper : (n - 1, 6, 6) array_like
        Blocks (i, i+1).
    lower : (n - 1, 6, 6) array_like, optional
        Blocks (i+1, i); the transposes of ``upper`` by default.

    Returns
    -------
    (6n, 6n) ndarray

    """
    diagonal = np.asarray(diagonal, dtype=float)
    upper = np.asarray(upper, dtype=float)
    lower = np.swapaxes(upper, 1, 2) if lower is None else np.asarray(lower, dtype=float)
    n, b = diagonal.shape[:2]
    out = np.zeros((n, b, n, b))
    idx = np.arange(n)
    out[idx, :, idx, :] = diagonal
    out[idx[:-1], :, idx[1:], :] = upper
    out[idx[1:], :, idx[:-1], :] = lower
    return out.reshape(n * b, n * b)


def chain_terms(model, state):
    """
    Evaluate the local terms of all links of a chain (shared by wrenches and tangent).

    Parameters
    ----------
    model : ChainModel
        The chain.
    state : ChainState
        Frame poses.

    Returns
    -------
    LinkTerms
        Batched over the n links.

    """
    pos = state.positions
    rot = state.rotations
    terms = link_terms(model.stiffnesses, model.rest_offsets, model.rest_rotations,
                       pos[:-1], rot[:-1], pos[1:], rot[1:])
    return terms


def _gather_wrenches(w_a, w_b):
    """Sum link wrenches onto frames 1..n: frame j gets w_b of link j-1 and w_a of link j."""
    internal = w_b.copy()
    internal[:-1] += w_a[1:]
    return internal


def _gather_blocks(rotation_a, local):
    """
    Rotate link tangents to world axes and add them into the BTD blocks of frames 1..n.

    Parameters
    ----------
    rotation_a : (n, 3, 3) ndarray
        World rotations of the a-frames (frames 0..n-1).
    local : (n, 12, 12) ndarray
        Link tangents in frame-a axes.

    Returns
    -------
    diagonal : (n, 6, 6) ndarray
        Symmetrised diagonal blocks (the fixed base block dropped).
    upper : (n - 1, 6, 6) ndarray

    """
    world = rotate_tangent(rotation_a, local)
    diagonal = world[:, 6:, 6:].copy()
    diagonal[:-1] += world[1:, :6, :6]
    diagonal += np.swapaxes(diagonal, 1, 2)
    diagonal *= 0.5
    return diagonal, world[1:, :6, 6:].copy()


def internal_wrenches(model, state, terms=None):
    """
    Total link wrench on frames 1..n (the elastic force f(q) of paper eq. 9).

    Parameters
    ----------
    model : ChainModel
        The chain.
    state : ChainState
        Frame poses.
    terms : LinkTerms, optional
        ``chain_terms(model, state)`` if already computed.

    Returns
    -------
    (n, 6) ndarray  [N, N*m]
        World axes, at each frame origin.

    """
    if terms is None:
        terms = chain_terms(model, state)
    w_a, w_b = wrench_pair_from_terms(terms, state.rotations[:-1])
    return _gather_wrenches(w_a, w_b)


def assemble_tangent(model, state, terms=None):
    """
    Assemble internal wrenches and the BTD tangent ``K = -d internal / d increments``.

    Per link the exact 12x12 tangent (material part, paper eq. 8, plus the geometric part; see
    :mod:`cbha_inverse.core.links`) is computed in frame-a axes, rotated to world axes and added
    into the blocks of its two frames; the block of the fixed base is dropped. The diagonal
    blocks are symmetrised (see :class:`TangentSystem`).

    Parameters
    ----------
    model : ChainModel
        The chain.
    state : ChainState
        Frame poses.
    terms : LinkTerms, optional
        ``chain_terms(model, state)`` if already computed.

    Returns
    -------
    TangentSystem

    """
    rot_a = state.rotations[:-1]
    if terms is None:
        terms = chain_terms(model, state)
    w_a, w_b = wrench_pair_from_terms(terms, rot_a)
    diagonal, upper = _gather_blocks(rot_a, local_tangent(terms, model.stiffnesses))
    return TangentSystem(_gather_wrenches(w_a, w_b), diagonal, upper)


def material_tangent(model, state, terms=None):
    """
    Material part of the chain tangent (paper eq. 8): symmetric positive definite BTD blocks.

    Per link ``B^T K B`` (:func:`local_material_tangent`), rotated to
    world axes and assembled over frames 1..n; no geometric (stress) part, so it stays positive
    definite whatever the loads.

    Parameters
    ----------
    model : ChainModel
        The chain.
    state : ChainState
        Frame poses.
    terms : LinkTerms, optional
        ``chain_terms(model, state)`` if already computed.

    Returns
    -------
    diagonal : (n, 6, 6) ndarray
    upper : (n - 1, 6, 6) ndarray

    """
    if terms is None:
        terms = chain_terms(model, state)
    return _gather_blocks(state.rotations[:-1],
                          local_material_tangent(terms, model.stiffnesses))
