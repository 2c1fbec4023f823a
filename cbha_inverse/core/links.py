"""
Compliance links between two 6-DoF frames: Timoshenko compliance, corotational wrench, tangent.

A link joins frame a (= frame i) to frame b (= frame i+1). Its data are a symmetric positive
definite 6x6 stiffness ``K = C^-1`` (C as the paper defines it: frame a clamped, loads at the
origin of frame b, all in frame-a axes; DESIGN §3, paper eq. 2-4) and the rest transform of frame
b seen from frame a (offset ``d0``, rotation ``Q0``).

Local deformation (DESIGN §3)::

    delta = [ R_a^T (x_b - x_a) - d0 ;  log(R_a^T R_b Q0^T) ]          (frame-a axes)

The link stores the energy ``U = delta^T K delta / 2``; its wrenches are the exact generalised
forces ``-dU/dq`` for world-axis increments (dx, dtheta) with ``R <- exp(dtheta) R``:

- on frame b, in frame-a axes at the origin of b: force ``-(K delta)_t`` (exactly DESIGN's
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
"""

from typing import NamedTuple

from cbha_inverse.core.se3 import (_jl_inv_coefficient, _jl_inv_from_hat, hat,
                                   so3_left_jacobian_inverse_transpose_derivative, so3_log,
                                   so3_log_angle)
import numpy as np


def cowper_shear_coefficient(poisson_ratio, outer_radius, inner_radius=0.0):
    """
    Cowper's shear coefficient of a solid or hollow circular section.

    ``kappa = 6 (1 + nu) (1 + m^2)^2 / ((7 + 6 nu) (1 + m^2)^2 + (20 + 12 nu) m^2)``, ``m =
    r_i / r_o`` (Cowper 1966); ``m = 0`` gives the solid value ``6 (1 + nu) / (7 + 6 nu)``.

    Parameters
    ----------
    poisson_ratio : float
        Poisson's ratio nu.
    outer_radius : float  [m]
        Outer radius r_o.
    inner_radius : float  [m]
        Inner radius r_i (0 for a solid section).

    Returns
    -------
    float

    """
    nu = float(poisson_ratio)
    m2 = (float(inner_radius) / float(outer_radius)) ** 2
    a = (1.0 + m2) ** 2
    return 6.0 * (1.0 + nu) * a / ((7.0 + 6.0 * nu) * a + (20.0 + 12.0 * nu) * m2)


def timoshenko_compliance(length, youngs_modulus, poisson_ratio, outer_radius, inner_radius=0.0):
    """
    Compliance of a straight Timoshenko beam along local +x (DESIGN §3).

    Frame a is clamped at x = 0; loads (Fx, Fy, Fz, Mx, My, Mz) act at the origin of frame b
    (x = L), displacements (dx, dy, dz, rx, ry, rz) are measured there, all in frame-a axes::

        C[0,0] = L/(EA)   C[3,3] = L/(GJ)   C[1,1] = C[2,2] = L^3/(3EI) + L/(kappa G A)
        C[4,4] = C[5,5] = L/(EI)   C[1,5] = C[5,1] = L^2/(2EI)   C[2,4] = C[4,2] = -L^2/(2EI)

    with G = E / (2 (1 + nu)), J = 2 I the polar moment and kappa Cowper's coefficient.

    Parameters
    ----------
    length : float  [m]
        Beam length L.
    youngs_modulus : float  [Pa]
        Young's modulus E.
    poisson_ratio : float
        Poisson's ratio nu.
    outer_radius : float  [m]
        Outer radius r_o.
    inner_radius : float  [m]
        Inner radius r_i, 0 for a solid section.

    Returns
    -------
    (6, 6) ndarray  [m/N, 1/N, rad/(N*m)]

    """
    length = float(length)
    e_mod = float(youngs_modulus)
    r_o = float(outer_radius)
    r_i = float(inner_radius)
    if not all(np.isfinite([length, e_mod, r_o, r_i, float(poisson_ratio)])):
        raise ValueError('length, youngs_modulus, poisson_ratio and radii must be finite')
    if length <= 0.0 or e_mod <= 0.0 or r_o <= 0.0 or not 0.0 <= r_i < r_o:
        raise ValueError('need length > 0, youngs_modulus > 0 and 0 <= inner < outer radius')
    if not -1.0 < poisson_ratio < 0.5:
        raise ValueError('poisson_ratio must lie in (-1, 0.5)')
    area = np.pi * (r_o ** 2 - r_i ** 2)
    inertia = np.pi * (r_o ** 4 - r_i ** 4) / 4.0
    shear_modulus = e_mod / (2.0 * (1.0 + poisson_ratio))
    kappa = cowper_shear_coefficient(poisson_ratio, r_o, r_i)
    ei = e_mod * inertia
    c = np.zeros((6, 6))
    c[0, 0] = length / (e_mod * area)
    c[1, 1] = c[2, 2] = length ** 3 / (3.0 * ei) + length / (kappa * shear_modulus * area)
    c[3, 3] = length / (shear_modulus * 2.0 * inertia)
    c[4, 4] = c[5, 5] = length / ei
    c[1, 5] = c[5, 1] = length ** 2 / (2.0 * ei)
    c[2, 4] = c[4, 2] = -length ** 2 / (2.0 * ei)
    return c


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
    Local deformation ``delta`` of links (DESIGN §3), frame-a axes.

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


def local_tangent_blocks(terms, stiffness):
    """
    Exact link tangent blocks in frame-a axes: ``T_aa``, ``T_ab``, ``T_bb`` (``T_ba = T_ab^T``).

    Parameters
    ----------
    terms : LinkTerms
        Local link quantities from :func:`link_terms`.
    stiffness : (..., 6, 6) ndarray
        Link stiffness K.

    Returns
    -------
    t_aa, t_ab, t_bb : (..., 6, 6) ndarrays

    """
    full = local_tangent(terms, stiffness)
    return full[..., :6, :6], full[..., :6, 6:], full[..., 6:, 6:]


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
