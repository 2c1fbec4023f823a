"""
Compiled kernels of one linearisation tick (numba): links, assembly, projection, outcome.

The reference path (:func:`cbha_inverse.core.assembly.assemble_tangent` and the actuators'
``evaluate`` / ``load_tangent``) is batched numpy; a tick of it is a few hundred numpy calls of
1-3 µs each, ten times the arithmetic. These kernels compute the same quantities (equal to
round-off, tested against the reference) in one pass per link, span and column:

- :func:`link_pass`, per link ``l`` (frames ``a = l``, ``b = l + 1``): the deformation ``δ``
  (DESIGN §3), the local b-side wrench ``L = [-s_f; -Jl⁻ᵀ(φ) s_r] + Σ_c p_c (G0_c + H_c δ)``
  (paper eq. 9 plus the condensed cavities of :mod:`cbha_inverse.core.cavity_linear`) rotated to
  world axes and gathered onto the two frames (paper eq. 5-7), and the 12 x 12 world tangent
  ``Dᵀ M D`` + geometric terms, ``M = (Bᵀ K + Z(dJ) - H_p) B`` (paper eq. 8 plus the exact
  cavity load stiffness);
- :func:`cbha_inverse.core.tick_cables.cable_pass`: the cables' columns, loads and stiffness;
- :func:`scatter_add`: every block value into the symmetric band storage by a constant index
  (factored by :mod:`cbha_inverse.core.band_kernels`);
- :func:`project_effectors` and :func:`tick_outcome`: ``W_ea``, ``W_aa``, the free effector
  positions, and the actuation and remaining gap of a QP solution.
"""

import math

from cbha_inverse.core.tick_math import jl_coefficient, rotation_log
import numba
import numpy as np


@numba.njit(cache=True)
def hat_into(v, out):
    """Write ``hat(v)`` (``hat(v) @ b = v x b``) into a (3, 3) array."""
    out[0, 0] = out[1, 1] = out[2, 2] = 0.0
    out[0, 1], out[0, 2] = -v[2], v[1]
    out[1, 0], out[1, 2] = v[2], -v[0]
    out[2, 0], out[2, 1] = -v[1], v[0]


@numba.njit(cache=True)
def _add_scaled_hat(out, v, weight):
    """Add ``weight * hat(v)`` to a (3, 3) array (view)."""
    out[0, 1] -= weight * v[2]
    out[1, 0] += weight * v[2]
    out[0, 2] += weight * v[1]
    out[2, 0] -= weight * v[1]
    out[1, 2] -= weight * v[0]
    out[2, 1] += weight * v[0]


@numba.njit(cache=True)
def link_pass(positions, rotations, stiffness, rest_offsets, rest_rotations_t, actuation,
              cavity_wrench, cavity_stiffness, rhs, blocks, material):
    """
    Write every link's wrenches into ``rhs`` and its world tangent into ``blocks``.

    Parameters
    ----------
    positions : (n + 1, 3) ndarray  [m]
        Frame origins.
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations.
    stiffness : (n, 6, 6) ndarray  [N/m, N, N*m/rad]
        Link stiffness ``K``.
    rest_offsets : (n, 3) ndarray  [m]
        ``d0``.
    rest_rotations_t : (n, 3, 3) ndarray
        ``Q0ᵀ``, or a (0, 3, 3) array when every ``Q0`` is the identity.
    actuation : (m,) ndarray  [Pa, N]
        ``λ`` (the cavity pressures enter the wrench and the load stiffness).
    cavity_wrench : (n, c, 6) ndarray  [N/Pa, N*m/Pa]
        ``G0`` of every condensed cavity part per link (``c = m`` with cavities, else 0).
    cavity_stiffness : (n, c, 6, 6) ndarray
        ``H`` of the same parts (derivative of the local wrench per unit pressure).
    rhs : (6n, m + 1) ndarray
        Zeroed here; receives the link wrenches (column 0) and, with cavities, ``J_aᵀ``
        (columns ``1 + c``).
    blocks : (n, 12, 12) ndarray
        Receives the link tangents ``-d[w_a; w_b]/d[dq_a; dq_b]`` in world axes, rows and
        columns (frame a, frame b): exact (not symmetric; material, geometric and cavity load
        stiffness), or with ``material`` the material part ``Dᵀ Bᵀ K B D`` alone (paper eq. 8,
        symmetric positive semi-definite whatever the loads).
    material : bool
        Write the material tangent instead of the exact one (the residual is the same).

    """
    n = stiffness.shape[0]
    n_cav = cavity_wrench.shape[1]
    kc = 1 + n_cav
    rhs[:, :] = 0.0
    rel = np.empty((3, 3))
    tmp = np.empty((3, 3))
    delta = np.empty(6)
    stress = np.empty(6)
    jinv = np.empty((3, 3))
    a = np.empty((6, 6))
    mat = np.empty((6, 6))
    rotated = np.empty((6, 6))
    local = np.empty((6, kc))
    world = np.empty((6, kc))
    diff = np.empty(3)
    diff_hat = np.empty((3, 3))
    f_hat = np.empty((3, 3))
    m_hat = np.empty((3, 3))
    for link in range(n):
        ra = rotations[link]
        rb = rotations[link + 1]
        for i in range(3):
            diff[i] = positions[link + 1, i] - positions[link, i]
        for i in range(3):
            for j in range(3):
                rel[i, j] = ra[0, i] * rb[0, j] + ra[1, i] * rb[1, j] + ra[2, i] * rb[2, j]
        if rest_rotations_t.shape[0] > 0:
            q0t = rest_rotations_t[link]
            tmp[:, :] = rel
            for i in range(3):
                for j in range(3):
                    rel[i, j] = (tmp[i, 0] * q0t[0, j] + tmp[i, 1] * q0t[1, j]
                                 + tmp[i, 2] * q0t[2, j])
        for i in range(3):
            delta[i] = (ra[0, i] * diff[0] + ra[1, i] * diff[1] + ra[2, i] * diff[2]
                        - rest_offsets[link, i])
        theta = rotation_log(rel, delta[3:])
        phi = delta[3:]
        t2 = theta * theta
        c, dc = jl_coefficient(theta)
        k = stiffness[link]
        for i in range(6):
            acc = 0.0
            for j in range(6):
                acc += k[i, j] * delta[j]
            stress[i] = acc
        # Jl^-1 = (1 - c t^2) I + c phi phi^T - hat(phi) / 2
        for i in range(3):
            for j in range(3):
                jinv[i, j] = c * phi[i] * phi[j]
            jinv[i, i] += 1.0 - c * t2
        _add_scaled_hat(jinv, phi, -0.5)
        # a = B^T K with B = diag(I, Jl^-1)
        for j in range(6):
            for i in range(3):
                a[i, j] = k[i, j]
                a[3 + i, j] = jinv[0, i] * k[3, j] + jinv[1, i] * k[4, j] + jinv[2, i] * k[5, j]
        # local b-side wrench: column 0 total (-B^T K delta + sum_c p_c (G0_c + H_c delta)),
        # columns 1.. per unit pressure
        for i in range(6):
            acc = 0.0
            for j in range(6):
                acc += a[i, j] * delta[j]
            local[i, 0] = -acc
        for cav in range(n_cav):
            p = actuation[cav]
            g0 = cavity_wrench[link, cav]
            h = cavity_stiffness[link, cav]
            for i in range(6):
                acc = g0[i]
                for j in range(6):
                    acc += h[i, j] * delta[j]
                local[i, 1 + cav] = acc
                local[i, 0] += p * acc
            # the exact tangent's cavity load stiffness: a -= p_c H_c
            if p != 0.0 and not material:
                for i in range(6):
                    for j in range(6):
                        a[i, j] -= p * h[i, j]
        # world axes; frame b gets the wrench, frame a the equilibrating one (moment at x_a)
        for col in range(kc):
            for part in range(2):
                for i in range(3):
                    world[3 * part + i, col] = (ra[i, 0] * local[3 * part, col]
                                                + ra[i, 1] * local[3 * part + 1, col]
                                                + ra[i, 2] * local[3 * part + 2, col])
        row_b = 6 * link
        row_a = 6 * (link - 1)
        for col in range(kc):
            for i in range(6):
                rhs[row_b + i, col] += world[i, col]
            if link > 0:
                for i in range(6):
                    rhs[row_a + i, col] -= world[i, col]
                rhs[row_a + 3, col] -= diff[1] * world[2, col] - diff[2] * world[1, col]
                rhs[row_a + 4, col] -= diff[2] * world[0, col] - diff[0] * world[2, col]
                rhs[row_a + 5, col] -= diff[0] * world[1, col] - diff[1] * world[0, col]
        if not material:
            # a[3:, 3:] += d(Jl^-T s_r)/dphi
            s_r = stress[3:]
            ps = phi[0] * s_r[0] + phi[1] * s_r[1] + phi[2] * s_r[2]
            for i in range(3):
                left0 = dc * (phi[i] * ps - t2 * s_r[i]) - 2.0 * c * s_r[i]
                left1 = c * phi[i]
                for j in range(3):
                    a[3 + i, 3 + j] += left0 * phi[j] + left1 * s_r[j]
                a[3 + i, 3 + i] += c * ps
            _add_scaled_hat(a[3:, 3:], s_r, -0.5)
        # mat = a B
        for i in range(6):
            for j in range(3):
                mat[i, j] = a[i, j]
                mat[i, 3 + j] = a[i, 3] * jinv[0, j] + a[i, 4] * jinv[1, j] + a[i, 5] * jinv[2, j]
        # D = d delta / d(q_a, q_b) = R^T E with R = diag(Ra, Ra) and E = [E_a, I],
        # E_a = [-I, d^; 0, -I]: the world tangent is E^T (R mat R^T) E, blocks
        # [E_a^T M E_a, E_a^T M; M E_a, M] for M = R mat R^T
        hat_into(diff, diff_hat)
        for p in range(2):
            for q in range(2):
                for i in range(3):
                    for j in range(3):
                        tmp[i, j] = (mat[3 * p + i, 3 * q] * ra[j, 0]
                                     + mat[3 * p + i, 3 * q + 1] * ra[j, 1]
                                     + mat[3 * p + i, 3 * q + 2] * ra[j, 2])
                for i in range(3):
                    for j in range(3):
                        rotated[3 * p + i, 3 * q + j] = (
                            ra[i, 0] * tmp[0, j] + ra[i, 1] * tmp[1, j] + ra[i, 2] * tmp[2, j])
        out = blocks[link]
        for i in range(6):
            for j in range(6):
                out[6 + i, 6 + j] = rotated[i, j]
            for j in range(3):
                # M E_a
                out[6 + i, j] = -rotated[i, j]
                out[6 + i, 3 + j] = (rotated[i, 0] * diff_hat[0, j]
                                     + rotated[i, 1] * diff_hat[1, j]
                                     + rotated[i, 2] * diff_hat[2, j] - rotated[i, 3 + j])
        for j in range(6):
            for i in range(3):
                # E_a^T M and E_a^T (M E_a)
                out[i, 6 + j] = -rotated[i, j]
                out[3 + i, 6 + j] = -(diff_hat[i, 0] * rotated[0, j]
                                      + diff_hat[i, 1] * rotated[1, j]
                                      + diff_hat[i, 2] * rotated[2, j]) - rotated[3 + i, j]
                out[i, j] = -out[6 + i, j]
                out[3 + i, j] = -(diff_hat[i, 0] * out[6, j] + diff_hat[i, 1] * out[7, j]
                                  + diff_hat[i, 2] * out[8, j]) - out[9 + i, j]
        if material:
            continue
        # geometric terms of the b-side world wrench (F, M) = R_a L: turning frame a turns it
        # (dF = -F^ dθ_a, dM = -M^ dθ_a) and the lever d = x_b - x_a of the a-side moment
        # -M - d x F moves with x_a, x_b
        hat_into(world[:3, 0], f_hat)
        hat_into(world[3:, 0], m_hat)
        for i in range(3):
            for j in range(3):
                out[i, 3 + j] -= f_hat[i, j]
                out[3 + i, j] += f_hat[i, j]
                out[3 + i, 6 + j] -= f_hat[i, j]
                out[6 + i, 3 + j] += f_hat[i, j]
                out[9 + i, 3 + j] += m_hat[i, j]
                out[3 + i, 3 + j] -= m_hat[i, j] + (diff_hat[i, 0] * f_hat[0, j]
                                                    + diff_hat[i, 1] * f_hat[1, j]
                                                    + diff_hat[i, 2] * f_hat[2, j])


@numba.njit(cache=True)
def scatter_add(index, values, weights, out):
    """
    Zero ``out`` and add ``weights * values`` at ``index`` (a compiled ``np.bincount``).

    Parameters
    ----------
    index : (V,) int ndarray
        Slot of every value in ``out``.
    values, weights : (V,) ndarray
        Values and their weights.
    out : (S,) ndarray
        Receives the sums.

    """
    out[:] = 0.0
    for i in range(index.size):
        out[index[i]] += weights[i] * values[i]


@numba.njit(cache=True)
def project_effectors(solved, rhs, positions, rotations, effector_frames, effector_offsets,
                      previous):
    """
    Project a solved tick onto the effectors and actuators (DESIGN §6 step 2).

    With ``solved = K⁻¹ [r, J_aᵀ]`` and the effector Jacobian ``J_e`` (block ``[I, -r^]`` on
    the effector's frame, ``r = R_f o``, :mod:`cbha_inverse.core.effectors`):
    ``W_ea = J_e K⁻¹ J_aᵀ``, ``W_aa = J_a K⁻¹ J_aᵀ`` and the free effector positions
    ``p_e + J_e K⁻¹ r``, returned relative to the previous actuation so that
    ``δ_free = offset - target`` (as :func:`cbha_inverse.core.inverse.project_constraints`).

    Parameters
    ----------
    solved : (6n, m + 1) ndarray
        ``K⁻¹ [r, J_aᵀ]``.
    rhs : (6n, m + 1) ndarray
        ``[r, J_aᵀ]``.
    positions : (n + 1, 3) ndarray  [m]
        Frame origins.
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations.
    effector_frames : (k,) int ndarray
        Frame of every effector (1..n).
    effector_offsets : (k, 3) ndarray  [m]
        Effector points in their frame's axes.
    previous : (m,) ndarray
        ``λ_prev``.

    Returns
    -------
    w_ea : (3k, m) ndarray  [m/N, m/Pa]
    w_aa : (m, m) ndarray
    offset : (3k,) ndarray  [m]
        ``p_e + J_e K⁻¹ r - W_ea λ_prev``.
    residual_norm : float  [N, N*m]
        ``|r|``.

    """
    size, width = solved.shape
    m = width - 1
    k = effector_frames.size
    moved = np.empty((3 * k, width))
    offset = np.empty(3 * k)
    for e in range(k):
        frame = effector_frames[e]
        rot = rotations[frame]
        lever = np.empty(3)
        for i in range(3):
            lever[i] = (rot[i, 0] * effector_offsets[e, 0] + rot[i, 1] * effector_offsets[e, 1]
                        + rot[i, 2] * effector_offsets[e, 2])
            offset[3 * e + i] = positions[frame, i] + lever[i]
        base = 6 * (frame - 1)
        for col in range(width):
            rx, ry, rz = solved[base + 3, col], solved[base + 4, col], solved[base + 5, col]
            # dp = dx + dθ x r
            moved[3 * e, col] = solved[base, col] + ry * lever[2] - rz * lever[1]
            moved[3 * e + 1, col] = solved[base + 1, col] + rz * lever[0] - rx * lever[2]
            moved[3 * e + 2, col] = solved[base + 2, col] + rx * lever[1] - ry * lever[0]
    w_ea = np.ascontiguousarray(moved[:, 1:])
    for row in range(3 * k):
        acc = offset[row] + moved[row, 0]
        for j in range(m):
            acc -= w_ea[row, j] * previous[j]
        offset[row] = acc
    w_aa = np.zeros((m, m))
    residual = 0.0
    for q in range(size):
        residual += rhs[q, 0] * rhs[q, 0]
        for i in range(m):
            weight = rhs[q, 1 + i]
            if weight != 0.0:
                for j in range(m):
                    w_aa[i, j] += weight * solved[q, 1 + j]
    return w_ea, w_aa, offset, math.sqrt(residual)


@numba.njit(cache=True)
def tick_outcome(w_ea, delta_free, scale, x, x_previous, lower_bounds, upper_bounds):
    """
    Return the actuation of a QP solution and the linear model's remaining effector gap.

    Parameters
    ----------
    w_ea : (3k, m) ndarray  [m/N, m/Pa]
        Effector-actuator compliance.
    delta_free : (3k,) ndarray  [m]
        ``δ_e^free`` (free effector positions minus targets).
    scale : (m,) ndarray
        ``σ``: ``λ = σ x``.
    x, x_previous : (m,) ndarray
        QP solution and the previous actuation, dimensionless.
    lower_bounds, upper_bounds : (m,) ndarray
        Actuator bounds.

    Returns
    -------
    actuation : (m,) ndarray  [N, Pa]
        ``σ x`` clipped into the bounds.
    gap : (3k,) ndarray  [m]
        ``W_ea λ + δ_free`` (paper eq. 11: predicted effector minus target).
    largest_gap : float  [m]
        Largest effector distance ``max_e |gap_e|``.
    largest_move : float
        ``max |x - x_previous|`` (dimensionless actuation change).

    """
    rows, m = w_ea.shape
    actuation = np.empty(m)
    largest_move = 0.0
    for j in range(m):
        actuation[j] = min(max(scale[j] * x[j], lower_bounds[j]), upper_bounds[j])
        largest_move = max(largest_move, abs(x[j] - x_previous[j]))
    gap = np.empty(rows)
    for r in range(rows):
        acc = delta_free[r]
        for j in range(m):
            acc += w_ea[r, j] * actuation[j]
        gap[r] = acc
    largest = 0.0
    for e in range(rows // 3):
        largest = max(largest, gap[3 * e] ** 2 + gap[3 * e + 1] ** 2 + gap[3 * e + 2] ** 2)
    return actuation, gap, math.sqrt(largest), largest_move
