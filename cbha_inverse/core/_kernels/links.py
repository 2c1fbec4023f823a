"""
Compiled pass over the compliance links (numba): deformation, wrenches, tangent blocks.

:func:`link_pass`, per link ``l`` (frames ``a = l``, ``b = l + 1``): the deformation ``δ``
(paper eq. 4-8), the local b-side wrench ``L = [-s_f; -Jl⁻ᵀ(φ) s_r] + Σ_c p_c (G0_c + H_c δ)``
(paper eq. 9 plus the condensed cavities of
:mod:`cbha_inverse.core.actuation.condensed_cavities`) rotated to world axes and gathered onto
the two frames (paper eq. 5-7), and the exact 12 x 12 world tangent ``Eᵀ R M Rᵀ E`` + the
geometric terms of the rotated wrench, ``M = (Bᵀ K + Z(dJ) - H_p) B`` (paper eq. 8 plus the
exact cavity load stiffness), or the material part alone. The one implementation of the link
equations: the control tick, the static solver, the scenes' forward model and the plant all run
it (through :class:`cbha_inverse.core.system.EquilibriumSystem`); the readable numpy version is
a test oracle (``test/oracles/chain_forces.py``).
"""

from cbha_inverse.core._kernels.so3 import (_add_scaled_hat, jl_coefficient,
                                            left_jacobian_inverse_into,
                                            rotation_log_scalars)
import numba
import numpy as np


@numba.njit(cache=True)
def link_pass(positions, rotations, stiffness, rest_offsets, rest_rotations_t, actuation,
              cavity_wrench, cavity_stiffness, cavity_columns, rhs, blocks, material):
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
    cavity_columns : (n, c) int ndarray
        Per link, the cavity columns whose ``G0`` or ``H`` is nonzero, then -1
        (:func:`nonzero_cavity_columns`): only those are computed (the others add exact zeros).
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
    link_pass_into(positions, rotations, stiffness, rest_offsets, rest_rotations_t, actuation,
                   cavity_wrench, cavity_stiffness, cavity_columns, rhs, blocks, material,
                   np.empty(link_work_size(cavity_wrench.shape[1])))


def nonzero_cavity_columns(cavity_wrench, cavity_stiffness):
    """
    Return the cavity columns of every link whose ``G0`` or ``H`` is nonzero, padded with -1.

    Parameters
    ----------
    cavity_wrench : (n, c, 6) ndarray  [N/Pa, N*m/Pa]
        ``G0`` per link and cavity column.
    cavity_stiffness : (n, c, 6, 6) ndarray
        ``H`` per link and cavity column.

    Returns
    -------
    (n, c) int64 ndarray
        Per link, its nonzero cavity columns in increasing order, then -1.

    """
    n, c = cavity_wrench.shape[:2]
    nonzero = (np.any(cavity_wrench != 0.0, axis=2)
               | np.any(cavity_stiffness.reshape((n, c, 36)) != 0.0, axis=2))
    columns = np.full((n, c), -1, dtype=np.int64)
    for link in range(n):
        active = np.flatnonzero(nonzero[link])
        columns[link, :active.size] = active
    return columns


@numba.njit(cache=True)
def link_work_size(n_cavities):
    """
    Return the length of the workspace of the link passes (``c`` cavity columns).

    :func:`link_pass_into` uses its first ``114 + 12 (1 + c)`` entries,
    :func:`link_pass_band_into` 144 more (one link's 12 x 12 block).
    """
    return 114 + 12 * (1 + n_cavities) + 144


@numba.njit(cache=True)
def link_pass_into(positions, rotations, stiffness, rest_offsets, rest_rotations_t, actuation,
                   cavity_wrench, cavity_stiffness, cavity_columns, rhs, blocks, material, work):
    """:func:`link_pass` with its workspace given, ``work`` (:func:`link_work_size`,)."""
    _link_pass(positions, rotations, stiffness, rest_offsets, rest_rotations_t, actuation,
               cavity_wrench, cavity_stiffness, cavity_columns, rhs, blocks, material, work[:0],
               0, False, work)


@numba.njit(cache=True)
def link_pass_band_into(positions, rotations, stiffness, rest_offsets, rest_rotations_t,
                        actuation, cavity_wrench, cavity_stiffness, cavity_columns, rhs, band,
                        work):
    """
    Write the link wrenches into ``rhs`` and add the tangent's symmetric part into a band.

    The pass of :func:`link_pass_into` (exact tangent, ``material`` False), which keeps of each
    link's 12 x 12 world tangent ``T`` only what the symmetric lower band needs: the lower
    triangle of ``(T + Tᵀ) / 2``, added straight into ``band`` (no assembly index, no weights;
    the base frame's rows and columns are left out). ``(Eᵀ R M Rᵀ E + its transpose) / 2 =
    Eᵀ R sym(M) Rᵀ E``: the 6 x 6 ``M`` is symmetrised first, so of the products with ``Ra`` and
    ``E_a`` only the blocks on and below the diagonal are formed, and the geometric terms enter by
    their symmetric part. The same tangent as the symmetric part of :func:`link_pass_into`'s
    blocks up to rounding (the sums are grouped differently).

    Parameters
    ----------
    positions, rotations, stiffness, rest_offsets, rest_rotations_t, actuation, cavity_wrench, \
cavity_stiffness, cavity_columns, rhs
        As :func:`link_pass` (``rhs`` zeroed, then the wrenches and ``J_aᵀ``).
    band : ((N + 1) w,) ndarray
        Lower band storage in C order, row ``c`` at ``c w``, ``band[c w + r - c] += K[r, c]``
        (``w = kd + 1``, :func:`cbha_inverse.core._kernels.band_assembly.band_rows`; ``kd >= 11``);
        added to, not zeroed.
    work : (link_work_size(c),) ndarray
        Workspace.

    """
    width = band.size // (rhs.shape[0] + 1)
    # (1, 12, 12) of literal shape and strides (float64), as :func:`_matrix_view`
    scratch = np.lib.stride_tricks.as_strided(work[work.size - 144:], (1, 12, 12),
                                              (1152, 96, 8))
    _link_pass(positions, rotations, stiffness, rest_offsets, rest_rotations_t, actuation,
               cavity_wrench, cavity_stiffness, cavity_columns, rhs, scratch, False, band, width,
               True, work)


@numba.njit(cache=True, inline='always')
def _link_pass(positions, rotations, stiffness, rest_offsets, rest_rotations_t, actuation,
               cavity_wrench, cavity_stiffness, cavity_columns, rhs, blocks, material, band, width,
               symmetric, work):
    """
    Run the pass of :func:`link_pass_into` or (``symmetric``) :func:`link_pass_band_into`.

    With ``symmetric`` every link's block is formed in ``blocks[0]`` (symmetric part, lower
    triangle) and added into ``band`` (rows of ``width`` slots). Inlined into both with a
    literal ``symmetric``: each compiles without the other's branches.
    """
    n = stiffness.shape[0]
    n_cav = cavity_wrench.shape[1]
    kc = 1 + n_cav
    rhs[:, :] = 0.0
    rel = _matrix_view(work, 0, 3, 3)
    tmp = _matrix_view(work, 9, 3, 3)
    delta = work[18:24]
    stress = work[24:30]
    jinv = _matrix_view(work, 30, 3, 3)
    a = _matrix_view(work, 39, 6, 6)
    mat = _matrix_view(work, 75, 6, 6)
    diff = work[111:114]
    local = _matrix_view(work, 114, 6, kc)
    world = _matrix_view(work, 114 + 6 * kc, 6, kc)
    # every view taken once, here: a view taken per link costs atomic reference counts
    phi = delta[3:]
    s_r = stress[3:]
    a_rr = a[3:, 3:]
    out = blocks[0]
    for link in range(n):
        for i in range(3):
            diff[i] = positions[link + 1, i] - positions[link, i]
        for i in range(3):
            for j in range(3):
                rel[i, j] = (rotations[link, 0, i] * rotations[link + 1, 0, j]
                             + rotations[link, 1, i] * rotations[link + 1, 1, j]
                             + rotations[link, 2, i] * rotations[link + 1, 2, j])
        if rest_rotations_t.shape[0] > 0:
            tmp[:, :] = rel
            for i in range(3):
                for j in range(3):
                    rel[i, j] = (tmp[i, 0] * rest_rotations_t[link, 0, j]
                                 + tmp[i, 1] * rest_rotations_t[link, 1, j]
                                 + tmp[i, 2] * rest_rotations_t[link, 2, j])
        for i in range(3):
            delta[i] = (rotations[link, 0, i] * diff[0] + rotations[link, 1, i] * diff[1]
                        + rotations[link, 2, i] * diff[2] - rest_offsets[link, i])
        theta, delta[3], delta[4], delta[5] = rotation_log_scalars(rel)
        t2 = theta * theta
        c, dc = jl_coefficient(theta)
        for i in range(6):
            acc = 0.0
            for j in range(6):
                acc += stiffness[link, i, j] * delta[j]
            stress[i] = acc
        left_jacobian_inverse_into(phi, theta, c, jinv)
        # a = B^T K with B = diag(I, Jl^-1)
        for j in range(6):
            for i in range(3):
                a[i, j] = stiffness[link, i, j]
                a[3 + i, j] = (jinv[0, i] * stiffness[link, 3, j]
                               + jinv[1, i] * stiffness[link, 4, j]
                               + jinv[2, i] * stiffness[link, 5, j])
        # local b-side wrench: column 0 total (-B^T K delta + sum_c p_c (G0_c + H_c delta)),
        # columns 1.. per unit pressure
        for i in range(6):
            acc = 0.0
            for j in range(6):
                acc += a[i, j] * delta[j]
            local[i, 0] = -acc
        used = 0
        for slot in range(n_cav):
            cav = cavity_columns[link, slot]
            if cav < 0:
                break
            used += 1
            p = actuation[cav]
            # the exact tangent's cavity load stiffness, a -= p_c H_c, in the same pass over H_c
            load = p != 0.0 and not material
            for i in range(6):
                acc = cavity_wrench[link, cav, i]
                for j in range(6):
                    h = cavity_stiffness[link, cav, i, j]
                    acc += h * delta[j]
                    if load:
                        a[i, j] -= p * h
                local[i, 1 + cav] = acc
                local[i, 0] += p * acc
        # world axes; frame b gets the wrench, frame a the equilibrating one (moment at x_a),
        # each column in scalar locals (LLVM keeps them in registers across the stores)
        row_b = 6 * link
        row_a = 6 * (link - 1)
        for slot in range(1 + used):
            col = 0 if slot == 0 else 1 + cavity_columns[link, slot - 1]
            f0, f1, f2 = _rotate_vector(rotations, link, local, 0, col)
            m0, m1, m2 = _rotate_vector(rotations, link, local, 3, col)
            world[0, col], world[1, col], world[2, col] = f0, f1, f2
            world[3, col], world[4, col], world[5, col] = m0, m1, m2
            rhs[row_b, col] += f0
            rhs[row_b + 1, col] += f1
            rhs[row_b + 2, col] += f2
            rhs[row_b + 3, col] += m0
            rhs[row_b + 4, col] += m1
            rhs[row_b + 5, col] += m2
            if link > 0:
                rhs[row_a, col] -= f0
                rhs[row_a + 1, col] -= f1
                rhs[row_a + 2, col] -= f2
                rhs[row_a + 3, col] -= m0
                rhs[row_a + 4, col] -= m1
                rhs[row_a + 5, col] -= m2
                rhs[row_a + 3, col] -= diff[1] * f2 - diff[2] * f1
                rhs[row_a + 4, col] -= diff[2] * f0 - diff[0] * f2
                rhs[row_a + 5, col] -= diff[0] * f1 - diff[1] * f0
        if not material:
            # a[3:, 3:] += d(Jl^-T s_r)/dphi
            ps = phi[0] * s_r[0] + phi[1] * s_r[1] + phi[2] * s_r[2]
            for i in range(3):
                left0 = dc * (phi[i] * ps - t2 * s_r[i]) - 2.0 * c * s_r[i]
                left1 = c * phi[i]
                for j in range(3):
                    a[3 + i, 3 + j] += left0 * phi[j] + left1 * s_r[j]
                a[3 + i, 3 + i] += c * ps
            _add_scaled_hat(a_rr, s_r, -0.5)
        # mat = a B
        for i in range(6):
            for j in range(3):
                mat[i, j] = a[i, j]
                mat[i, 3 + j] = a[i, 3] * jinv[0, j] + a[i, 4] * jinv[1, j] + a[i, 5] * jinv[2, j]
        # D = d delta / d(q_a, q_b) = R^T E with R = diag(Ra, Ra) and E = [E_a, I],
        # E_a = [-I, d^; 0, -I]: the world tangent is E^T (R mat R^T) E, blocks
        # [E_a^T M E_a, E_a^T M; M E_a, M] for M = R mat R^T
        # the hat matrices as locals (LLVM keeps them in registers)
        d0, d1, d2 = diff[0], diff[1], diff[2]
        if symmetric:
            # sym(mat): then M = R mat R^T is symmetric, its block (0, 1) the transpose of (1, 0)
            for i in range(1, 6):
                for j in range(i):
                    s = 0.5 * (mat[i, j] + mat[j, i])
                    mat[i, j] = s
                    mat[j, i] = s
            _rotate_block(mat, rotations, link, out, 0, 0)
            _rotate_block(mat, rotations, link, out, 3, 0)
            _rotate_block(mat, rotations, link, out, 3, 3)
            for i in range(3):
                for j in range(3):
                    out[6 + i, 9 + j] = out[9 + j, 6 + i]
        else:
            out = blocks[link]
            # M = R mat R^T straight into its block of out, read back there
            for p in range(2):
                for q in range(2):
                    _rotate_block(mat, rotations, link, out, 3 * p, 3 * q)
        # the products with d^ written out term by term (the zero terms of the hat matrix
        # dropped: x + 0 y = x for finite y), no tuple indexed by a loop variable
        for i in range(6):
            # M E_a
            r = 6 + i
            x0, x1, x2 = out[r, 6], out[r, 7], out[r, 8]
            out[r, 0] = -x0
            out[r, 1] = -x1
            out[r, 2] = -x2
            out[r, 3] = x1 * d2 - x2 * d1 - out[r, 9]
            out[r, 4] = x2 * d0 - x0 * d2 - out[r, 10]
            out[r, 5] = x0 * d1 - x1 * d0 - out[r, 11]
        # (symmetric: the block (0, 1), E_a^T M, is above the diagonal)
        for c in range(6 if symmetric else 12):
            # E_a^T M and E_a^T (M E_a), column c
            y0, y1, y2 = out[6, c], out[7, c], out[8, c]
            out[0, c] = -y0
            out[1, c] = -y1
            out[2, c] = -y2
            out[3, c] = -(y2 * d1 - d2 * y1) - out[9, c]
            out[4, c] = -(d2 * y0 - d0 * y2) - out[10, c]
            out[5, c] = -(d0 * y1 - d1 * y0) - out[11, c]
        if symmetric:
            _add_symmetric_geometric(out, world, d0, d1, d2)
            _add_lower_into_band(out, band, width, 6 * (link - 1))
            continue
        if material:
            continue
        # geometric terms of the b-side world wrench (F, M) = R_a L: turning frame a turns it
        # (dF = -F^ dθ_a, dM = -M^ dθ_a) and the lever d = x_b - x_a of the a-side moment
        # -M - d x F moves with x_a, x_b: the blocks -F^ at (0, 3), F^ at (3, 0), -F^ at
        # (3, 6), F^ at (6, 3), M^ at (9, 3) and -(M^ + d^ F^) at (3, 3)
        f0, f1, f2 = world[0, 0], world[1, 0], world[2, 0]
        m0, m1, m2 = world[3, 0], world[4, 0], world[5, 0]
        _add_hat(out, 0, 3, -f0, -f1, -f2)
        _add_hat(out, 3, 0, f0, f1, f2)
        _add_hat(out, 3, 6, -f0, -f1, -f2)
        _add_hat(out, 6, 3, f0, f1, f2)
        _add_hat(out, 9, 3, m0, m1, m2)
        out[3, 3] -= -(d2 * f2) - d1 * f1
        out[3, 4] -= d1 * f0 - m2
        out[3, 5] -= m1 + d2 * f0
        out[4, 3] -= m2 + d0 * f1
        out[4, 4] -= -(d2 * f2) - d0 * f0
        out[4, 5] -= d2 * f1 - m0
        out[5, 3] -= d0 * f2 - m1
        out[5, 4] -= m0 + d1 * f2
        out[5, 5] -= -(d1 * f1) - d0 * f0


@numba.njit(cache=True, inline='always')
def _matrix_view(work, start, rows, cols):
    """
    Return ``work[start:start + rows cols]`` (float64) as a (rows, cols) matrix in C order.

    A view with its shape and strides given (``as_strided``), where ``reshape`` gets them from
    a library call opaque to LLVM: with literal ``rows`` and ``cols`` the view's addresses are
    constants and LLVM tells the workspace's matrices apart. The strides are literal bytes:
    ``work.itemsize`` is read at run time (the compiled CBHA tick 13.9 against 13.3 µs).
    """
    return np.lib.stride_tricks.as_strided(work[start:start + rows * cols], (rows, cols),
                                           (8 * cols, 8))


@numba.njit(cache=True, inline='always')
def _add_symmetric_geometric(out, world, d0, d1, d2):
    """
    Add the symmetric part of a link's geometric terms to the lower triangle of its block.

    The terms of :func:`link_pass_into` (``F``, ``M`` the b-side world wrench, column 0 of
    ``world``): the pairs ``-F^`` at (0, 3) / ``F^`` at (3, 0) and ``-F^`` at (3, 6) / ``F^`` at
    (6, 3) are each other's transposes (``F^`` stays below the diagonal), ``M^`` at (9, 3) has a
    zero mirror (half of it stays) and of ``-(M^ + d^ F^)`` at (3, 3) the symmetric part is
    ``-(d^ F^ + F^ d^) / 2``, ``d^ F^ = F dᵀ - (d·F) I``.
    """
    f0, f1, f2 = world[0, 0], world[1, 0], world[2, 0]
    _add_hat(out, 3, 0, f0, f1, f2)
    _add_hat(out, 6, 3, f0, f1, f2)
    _add_hat(out, 9, 3, 0.5 * world[3, 0], 0.5 * world[4, 0], 0.5 * world[5, 0])
    out[3, 3] -= -(d2 * f2) - d1 * f1
    out[4, 3] -= 0.5 * (d0 * f1 + d1 * f0)
    out[4, 4] -= -(d2 * f2) - d0 * f0
    out[5, 3] -= 0.5 * (d0 * f2 + d2 * f0)
    out[5, 4] -= 0.5 * (d1 * f2 + d2 * f1)
    out[5, 5] -= -(d1 * f1) - d0 * f0


@numba.njit(cache=True, inline='always')
def _add_lower_into_band(out, band, width, dof):
    """
    Add the lower triangle of a link's 12 x 12 block into a lower band (C order, rows ``width``).

    Entry ``(i, j)``, ``i >= j``, of the block at unknowns ``(dof + i, dof + j)`` goes to slot
    ``(dof + j) width + i - j``; with ``dof < 0`` (the first link) frame a is the base: its rows
    and columns are left out.
    """
    if dof >= 0:
        for j in range(6):
            row = (dof + j) * width - j
            for i in range(j, 12):
                band[row + i] += out[i, j]
    # (two loops of constant trip counts, fully unrolled)
    for j in range(6, 12):
        row = (dof + j) * width - j
        for i in range(j, 12):
            band[row + i] += out[i, j]


@numba.njit(cache=True, inline='always')
def _add_hat(out, r0, c0, v0, v1, v2):
    """Add ``hat(v)`` to the 3 x 3 block of ``out`` at ``(r0, c0)`` (its diagonal is zero)."""
    out[r0, c0 + 1] -= v2
    out[r0, c0 + 2] += v1
    out[r0 + 1, c0] += v2
    out[r0 + 1, c0 + 2] -= v0
    out[r0 + 2, c0] -= v1
    out[r0 + 2, c0 + 1] += v0


@numba.njit(cache=True, inline='always')
def _rotate_vector(rotations, link, local, r0, col):
    """Return ``Ra v``, ``v`` rows ``r0 .. r0 + 2`` of column ``col`` of ``local``, as floats."""
    v0, v1, v2 = local[r0, col], local[r0 + 1, col], local[r0 + 2, col]
    return (rotations[link, 0, 0] * v0 + rotations[link, 0, 1] * v1 + rotations[link, 0, 2] * v2,
            rotations[link, 1, 0] * v0 + rotations[link, 1, 1] * v1 + rotations[link, 1, 2] * v2,
            rotations[link, 2, 0] * v0 + rotations[link, 2, 1] * v1 + rotations[link, 2, 2] * v2)


@numba.njit(cache=True, inline='always')
def _rotate_block(mat, rotations, link, out, r0, c0):
    """
    Write ``Ra T Raᵀ``, ``T`` the 3 x 3 block of ``mat`` at ``(r0, c0)``, into ``out``.

    ``(T Raᵀ)`` first, then ``Ra (T Raᵀ)``, each sum left to right, in scalar locals (LLVM keeps
    them in registers, where a workspace array makes it store and reload them), written at
    ``(6 + r0, 6 + c0)`` of the link's 12 x 12 block (~0.5 µs of the CBHA's 16 links).
    ``Ra = rotations[link]`` is read in place (a view of it would cost reference counts).
    """
    r00, r01, r02 = rotations[link, 0, 0], rotations[link, 0, 1], rotations[link, 0, 2]
    r10, r11, r12 = rotations[link, 1, 0], rotations[link, 1, 1], rotations[link, 1, 2]
    r20, r21, r22 = rotations[link, 2, 0], rotations[link, 2, 1], rotations[link, 2, 2]
    m00, m01, m02 = mat[r0, c0], mat[r0, c0 + 1], mat[r0, c0 + 2]
    m10, m11, m12 = mat[r0 + 1, c0], mat[r0 + 1, c0 + 1], mat[r0 + 1, c0 + 2]
    m20, m21, m22 = mat[r0 + 2, c0], mat[r0 + 2, c0 + 1], mat[r0 + 2, c0 + 2]
    t00 = m00 * r00 + m01 * r01 + m02 * r02
    t01 = m00 * r10 + m01 * r11 + m02 * r12
    t02 = m00 * r20 + m01 * r21 + m02 * r22
    t10 = m10 * r00 + m11 * r01 + m12 * r02
    t11 = m10 * r10 + m11 * r11 + m12 * r12
    t12 = m10 * r20 + m11 * r21 + m12 * r22
    t20 = m20 * r00 + m21 * r01 + m22 * r02
    t21 = m20 * r10 + m21 * r11 + m22 * r12
    t22 = m20 * r20 + m21 * r21 + m22 * r22
    r0 += 6
    c0 += 6
    out[r0, c0] = r00 * t00 + r01 * t10 + r02 * t20
    out[r0, c0 + 1] = r00 * t01 + r01 * t11 + r02 * t21
    out[r0, c0 + 2] = r00 * t02 + r01 * t12 + r02 * t22
    out[r0 + 1, c0] = r10 * t00 + r11 * t10 + r12 * t20
    out[r0 + 1, c0 + 1] = r10 * t01 + r11 * t11 + r12 * t21
    out[r0 + 1, c0 + 2] = r10 * t02 + r11 * t12 + r12 * t22
    out[r0 + 2, c0] = r20 * t00 + r21 * t10 + r22 * t20
    out[r0 + 2, c0 + 1] = r20 * t01 + r21 * t11 + r22 * t21
    out[r0 + 2, c0 + 2] = r20 * t02 + r21 * t12 + r22 * t22
