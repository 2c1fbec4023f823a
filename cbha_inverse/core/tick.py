"""
Fused linearisation of one inverse-solver tick: chain, cables and condensed cavities at once.

The reference path of a tick (:func:`cbha_inverse.core.assembly.assemble_tangent` for the chain,
``ActuatorSet.evaluate`` / ``load_tangent`` for the actuators, DESIGN §6 step 1) builds several
dense ``6n x 6n`` matrices and calls numpy a few hundred times. :class:`TickModel` computes the
same quantities (equal to round-off, tested) in a few dozen batched calls:

- per link ``l`` (frames ``a = l``, ``b = l + 1``) the local b-side wrench
  ``L = [-s_f; -Jl⁻ᵀ(φ) s_r] + Σ_c p_c (G0_c + H_c δ)`` (the elastic wrench of paper eq. 9 plus
  the condensed cavities of :mod:`cbha_inverse.core.cavity_linear`, which live on the same
  segments), rotated to world axes once and gathered onto the frames (the a side receives the
  equilibrating wrench);
- the link tangent in world axes ``Dᵀ M D + geometric terms`` with ``M = (Bᵀ K + Z(dJ) - H_p) B``,
  ``D = dδ/dq`` (6 x 12) and ``H_p = Σ_c p_c H_c``: the structural tangent of paper eq. 8 plus
  the exact cavity load stiffness, in one 12 x 12 block per link;
- cable columns and load stiffness per span, summed per frame pair by a constant matrix;
- every block is added into the lower triangle of the dense tangent by one ``bincount`` with a
  constant index that also symmetrises (weights ½ on the mirrored entries), which is the
  symmetric tangent the reference solver factors.

Actuator groups other than :class:`~cbha_inverse.core.actuation.CableGroup` and
:class:`~cbha_inverse.core.cavity_linear.LinearCavityGroup` (e.g. the skinned mesh cavities) are
evaluated through their own ``evaluate`` / ``load_tangent`` (slower, same result).
"""

from cbha_inverse.core.actuation import CableGroup
from cbha_inverse.core.cavity_linear import LinearCavityGroup
from cbha_inverse.core.se3 import HAT_BASIS, LOG_BASIS, so3_log
from cbha_inverse.core.tick_cables import CableTerms
from cbha_inverse.core.tick_math import HALF_HAT_BASIS, hats_into, jl_coefficients
import numpy as np
from scipy.linalg import lapack


# (F0, M0, F1, M1, F2, M2) -> flattened [-2 hat(F); -hat(F); 2 hat(F); hat(M)] (12 x 3)
_GEOMETRIC_BASIS = np.zeros((6, 36))
_GEOMETRIC_BASIS[0::2, 0:9] = -2.0 * HAT_BASIS
_GEOMETRIC_BASIS[0::2, 9:18] = -HAT_BASIS
_GEOMETRIC_BASIS[0::2, 18:27] = 2.0 * HAT_BASIS
_GEOMETRIC_BASIS[1::2, 27:36] = HAT_BASIS


class TickModel:
    """
    Preallocated fused evaluator of everything a linearisation tick needs.

    Parameters
    ----------
    model : cbha_inverse.core.chain.ChainModel
        The chain.
    actuators : cbha_inverse.core.actuation.ActuatorSet
        The actuators (``m``).
    external : (6n,) ndarray  [N, N*m]
        Constant external wrenches on frames 1..n (gravity).

    """

    def __init__(self, model, actuators, external):
        """Precompute constants, buffers and the assembly index."""
        n = model.n_links
        m = actuators.n_actuators
        self.n, self.m, self.size = n, m, 6 * n
        self.stiffness = np.ascontiguousarray(model.stiffnesses)
        self.rest_offsets = np.ascontiguousarray(model.rest_offsets)
        q0 = np.asarray(model.rest_rotations)
        self._q0t = (None if np.array_equal(q0, np.broadcast_to(np.eye(3), q0.shape))
                     else np.ascontiguousarray(np.swapaxes(q0, 1, 2)))
        self.external = np.asarray(external, dtype=float).reshape(-1)
        position = {name: k for k, name in enumerate(actuators.names)}
        self._cables, self._generic = [], []
        g0 = np.zeros((n, m, 6))
        hess = np.zeros((n, m, 6, 6))
        has_cavities = False
        for group in actuators.groups:
            cols = [position[name] for name in group.names]
            if isinstance(group, CableGroup):
                self._cables.append(CableTerms(group, cols, model.n_frames))
            elif isinstance(group, LinearCavityGroup) and _matches_links(group, model):
                for e in range(group.lower.size):
                    col = cols[group.owner[e]]
                    g0[group.lower[e], col] += group.g0[e]
                    hess[group.lower[e], col] += group.hessian[e]
                has_cavities = True
            else:
                self._generic.append((group, np.asarray(cols, dtype=int)))
        self.has_cavities = has_cavities
        if has_cavities:
            # per link: every cavity's local wrench G0 + H δ as one (6m x 6) product
            self._g0_rows = g0.reshape(n, 6 * m)
            self._hess_rows = hess.reshape(n, 6 * m, 6)
            self._hess_t = np.ascontiguousarray(hess.reshape(n, m, 36).transpose(0, 2, 1))
            self._g0_t = np.ascontiguousarray(g0.transpose(0, 2, 1))
        kc = m + 1 if has_cavities else 1
        self._kc = kc
        self._local = np.zeros((n, 3, 2, kc))
        self._gather = np.zeros((n + 1, 2, 3, m + 1))
        self._delta = np.empty((n, 6))
        self._phi_hat = np.zeros((n, 3, 3))
        self._diff_hat = np.zeros((n, 3, 3))
        self._panel = np.empty((n, 12, 3))
        self._b = np.zeros((n, 6, 6))
        self._b[:, :3, :3] = np.eye(3)
        self._bt = self._b.copy()
        self._d = np.zeros((n, 6, 12))
        self._eye_minus = -np.eye(3)
        # values of the assembly: link blocks, cable pair blocks, cable point moments
        rows, cols = [], []
        f = np.arange(n)
        i12 = np.arange(12)
        link_dof = 6 * f[:, None] + i12[None, :] - 6          # frame a = l -> dof 6(l - 1)
        rows.append(np.broadcast_to(link_dof[:, :, None], (n, 12, 12)).reshape(-1))
        cols.append(np.broadcast_to(link_dof[:, None, :], (n, 12, 12)).reshape(-1))
        self._cable_slices = []
        count = n * 144
        for cab in self._cables:
            i6 = np.arange(6)
            for a, b in cab.pairs:
                dof = np.concatenate([6 * (a - 1) + i6, 6 * (b - 1) + i6])
                rows.append(np.repeat(dof, 12))
                cols.append(np.tile(dof, 12))
            i3 = np.arange(3)
            for fr in cab.moment_frames:
                dof = 6 * (fr - 1) + 3 + i3
                rows.append(np.repeat(dof, 3))
                cols.append(np.tile(dof, 3))
            n_pair, n_mom = len(cab.pairs) * 144, len(cab.moment_frames) * 9
            self._cable_slices.append((slice(count, count + n_pair),
                                       slice(count + n_pair, count + n_pair + n_mom)))
            count += n_pair + n_mom
        rows, cols = np.concatenate(rows), np.concatenate(cols)
        size = self.size
        valid = (rows >= 0) & (cols >= 0)
        lo, hi = np.minimum(rows, cols), np.maximum(rows, cols)
        # dense C-order slot of the lower triangle (row >= col); base-frame entries -> trash
        self._weights = np.where(rows == cols, 1.0, 0.5)
        # long chains without generic groups: LAPACK band Cholesky (band storage, lower: entry
        # (r, c) at [c, r - c] of a C-order (N, kd + 1) array = the Fortran (kd + 1, N) layout)
        kd = int((hi - lo)[valid].max())
        self.banded = size >= 72 and not self._generic and kd < size // 4
        if self.banded:
            self.kd = kd
            self._index = np.where(valid, lo * (kd + 1) + hi - lo, size * (kd + 1))
            c, d = np.meshgrid(np.arange(size), np.arange(kd + 1), indexing='ij')
            inside = (c + d < size).reshape(-1)
            self._band_src = np.flatnonzero(inside)
            # the factor L as the C-order transpose (L[r, c] at [c, r])
            self._dense_dst = (c * size + c + d).reshape(-1)[inside]
            self._factor = np.zeros((size, size))
        else:
            self._index = np.where(valid, hi * size + lo, size * size)
        self._values = np.zeros(count)
        self._link_values = self._values[:n * 144].reshape(n, 12, 12)

    def linearise(self, positions, rotations, actuation):
        """
        Return the symmetric tangent (lower triangle) and the right-hand sides of a tick.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations.
        actuation : (m,) ndarray
            ``λ_prev`` (enters the residual and the load stiffness).

        Returns
        -------
        tangent : ndarray
            ``K`` (structure + symmetric load stiffness) for :meth:`factor_solve`: for short
            chains a C-order (6n, 6n) array whose lower triangle holds ``K`` (strict upper
            triangle zero), for long ones (:attr:`banded`) the LAPACK lower band storage
            (kd + 1, 6n); :meth:`dense` converts either.
        rhs : (6n, m + 1) ndarray
            Column 0: the residual ``f(q) + f_ext + J_aᵀ λ``; columns 1..m: ``J_aᵀ``.

        """
        n = self.n
        rot_a = rotations[:-1]
        rot_at = rot_a.transpose(0, 2, 1)
        diff = positions[1:] - positions[:-1]
        rel = np.matmul(rot_at, rotations[1:])
        if self._q0t is not None:
            rel = np.matmul(rel, self._q0t)
        mixed = rel.reshape(n, 9) @ LOG_BASIS
        cos_t = mixed[:, 3] - 0.5
        delta = self._delta
        np.subtract(np.matmul(rot_at, diff[:, :, None])[:, :, 0], self.rest_offsets,
                    out=delta[:, :3])
        if cos_t.min() > -0.5:
            d = mixed[:, :3]
            sin_t = np.sqrt(np.einsum('ni,ni->n', d, d))
            theta = np.arctan2(sin_t, cos_t)
            np.multiply(d, (theta / np.maximum(sin_t, 1e-300))[:, None], out=delta[:, 3:])
        else:
            delta[:, 3:] = so3_log(rel)
            theta = np.sqrt(np.einsum('ni,ni->n', delta[:, 3:], delta[:, 3:]))
        phi = delta[:, 3:]
        t2 = theta * theta
        stress = np.matmul(self.stiffness, delta[:, :, None])[:, :, 0]
        c, dc = jl_coefficients(theta, t2)
        phi_hat = hats_into(self._phi_hat, phi)
        outer = phi[:, :, None] * phi[:, None, :]
        jinv = c[:, None, None] * outer - 0.5 * phi_hat
        jinv.reshape(n, 9)[:, ::4] += (1.0 - c * t2)[:, None]
        jinv_t = jinv.transpose(0, 2, 1)
        s_r = stress[:, 3:]
        b = self._b
        b[:, 3:, 3:] = jinv
        bt = self._bt
        bt[:, 3:, 3:] = jinv_t
        # a = Bᵀ K - H_p (B = diag(I, Jl⁻¹), H_p = Σ p_c H_c): the local b-side wrench of every
        # link with its cavities is L = G0_p - a δ (elastic part -[s_f; Jl⁻ᵀ s_r])
        a = np.matmul(bt, self.stiffness)
        local = self._local
        if self.has_cavities:
            a -= (self._hess_t @ actuation).reshape(n, 6, 6)
            wrench = np.matmul(a, delta[:, :, None])[:, :, 0]
            wrench -= self._g0_t @ actuation
            cav = np.matmul(self._hess_rows, delta[:, :, None])[:, :, 0]
            cav += self._g0_rows
            local[..., 1:] = cav.reshape(n, -1, 2, 3).transpose(0, 3, 2, 1)
        else:
            wrench = np.matmul(a, delta[:, :, None])[:, :, 0]
        np.negative(wrench.reshape(n, 2, 3).transpose(0, 2, 1), out=local[..., 0])
        world = np.matmul(rot_a, local.reshape(n, 3, -1)).reshape(n, 3, 2, -1)
        diff_hat = hats_into(self._diff_hat, diff)
        force = world[:, :, 0, :]
        arm = np.matmul(diff_hat, force)
        kc = self._kc
        gather = self._gather
        wt = world.transpose(0, 2, 1, 3)
        gather[1:, :, :, :kc] = wt
        gather[1:-1, :, :, :kc] -= wt[1:]
        gather[1:-1, 1, :, :kc] -= arm[1:]
        rhs = gather[1:].reshape(6 * n, -1)
        # tangent blocks per link, world axes: D^T M D + geometric terms
        # dj = d(Jl^-T s)/dphi (see se3.so3_left_jacobian_inverse_transpose_derivative)
        ps = np.einsum('ni,ni->n', phi, s_r)
        left = np.empty((n, 3, 2))
        np.subtract(dc[:, None] * (phi * ps[:, None] - t2[:, None] * s_r),
                    2.0 * c[:, None] * s_r, out=left[:, :, 0])
        np.multiply(c[:, None], phi, out=left[:, :, 1])
        right = np.empty((n, 2, 3))
        right[:, 0] = phi
        right[:, 1] = s_r
        dj = np.matmul(left, right)
        dj_flat = dj.reshape(n, 9)
        dj_flat += s_r @ HALF_HAT_BASIS
        dj_flat[:, ::4] += (c * ps)[:, None]
        a[:, 3:, 3:] += dj
        mat = np.matmul(a, b)
        dmat = self._d
        dmat[:, :3, 6:9] = rot_at
        dmat[:, 3:, 9:12] = rot_at
        np.negative(rot_at, out=dmat[:, :3, 0:3])
        dmat[:, 3:, 3:6] = dmat[:, :3, 0:3]
        np.matmul(rot_at, diff_hat, out=dmat[:, :3, 3:6])
        blocks = self._link_values
        np.matmul(dmat.transpose(0, 2, 1), np.matmul(mat, dmat), out=blocks)
        # geometric terms (b-side force F, moment M): only their symmetric part matters, so they
        # all fit in the a-rotation columns: [-2F^; -F^ d^; 2F^; M^] (d = x_b - x_a)
        panel = self._panel
        np.matmul(world[:, :, :, 0].reshape(n, 6), _GEOMETRIC_BASIS, out=panel.reshape(n, 36))
        np.matmul(panel[:, 3:6], diff_hat, out=panel[:, 3:6])
        blocks[:, :, 3:6] += panel
        for cab, (pair_slice, moment_slice) in zip(self._cables, self._cable_slices):
            cab.evaluate(positions, rotations, actuation, rhs, self._values[pair_slice],
                         self._values[moment_slice], self.has_cavities)
        rhs[:, 0] += self.external
        if self.banded:
            band = np.bincount(self._index, self._values * self._weights,
                               minlength=self.size * (self.kd + 1) + 1)[:-1]
            return band.reshape(self.size, self.kd + 1).T, rhs
        tangent = np.bincount(self._index, self._values * self._weights,
                              minlength=self.size * self.size + 1)[:-1]
        tangent = tangent.reshape(self.size, self.size)
        for group, cols in self._generic:
            wrenches, _ = group.evaluate(positions, rotations, False)
            jat = wrenches[:, 1:, :].reshape(wrenches.shape[0], -1)
            rhs[:, 1 + cols] = jat.T
            rhs[:, 0] += actuation[cols] @ jat
            load = group.load_tangent(positions, rotations, actuation[cols], True) if hasattr(
                group, 'load_tangent') else None
            if load is not None:
                tangent += np.tril(0.5 * (load + load.T))
        return tangent, rhs

    def factor(self, tangent):
        """
        Factor the tangent of :meth:`linearise` in place (LAPACK Cholesky).

        Parameters
        ----------
        tangent : ndarray
            From :meth:`linearise` (overwritten).

        Returns
        -------
        tuple or None
            ``(factor, lower)`` for :meth:`solve` (Fortran-order triangle, LAPACK ``lower``
            flag); ``None`` if the tangent is not positive definite.

        """
        if self.banded:
            band, info = lapack.dpbtrf(tangent, lower=1, overwrite_ab=1)
            if info != 0:
                return None
            # dpbtrs is slow for several right-hand sides: solve with the dense triangle
            factor = self._factor
            factor.reshape(-1)[self._dense_dst] = band.T.reshape(-1)[self._band_src]
            return factor.T, 1
        # the C-order lower triangle is the Fortran upper one
        factor, info = lapack.dpotrf(tangent.T, lower=0, clean=0, overwrite_a=1)
        return (factor, 0) if info == 0 else None

    @staticmethod
    def solve(factor, rhs):
        """
        Solve ``K X = rhs`` with a factor of :meth:`factor` (one multi-RHS LAPACK call).

        Parameters
        ----------
        factor : tuple
            From :meth:`factor`.
        rhs : (6n, c) ndarray
            Right-hand sides.

        Returns
        -------
        (6n, c) ndarray

        """
        solved, info = lapack.dpotrs(factor[0], rhs, lower=factor[1])
        if info != 0:
            raise np.linalg.LinAlgError(f'dpotrs failed (info {info})')
        return solved

    def factor_solve(self, tangent, rhs):
        """
        Return ``K⁻¹ rhs`` (:meth:`factor` then :meth:`solve`), ``None`` if not positive definite.

        Parameters
        ----------
        tangent : ndarray
            From :meth:`linearise` (overwritten).
        rhs : (6n, c) ndarray
            Right-hand sides.

        Returns
        -------
        (6n, c) ndarray or None

        """
        factor = self.factor(tangent)
        return None if factor is None else self.solve(factor, rhs)

    def dense(self, tangent):
        """
        Return the lower triangle of the tangent of :meth:`linearise` as a full square matrix.

        Parameters
        ----------
        tangent : ndarray
            From :meth:`linearise` (band or dense storage).

        Returns
        -------
        (6n, 6n) ndarray

        """
        if not self.banded:
            return np.array(tangent)
        out = np.zeros((self.size, self.size))
        out.reshape(-1)[self._dense_dst] = tangent.T.reshape(-1)[self._band_src]
        return out.T.copy()


def _matches_links(group, model):
    """Whether every condensed cavity part has the rest geometry of its link."""
    lower = group.lower
    if lower.size == 0 or lower.min() < 0 or lower.max() >= model.n_links:
        return False
    return bool(np.allclose(group.rest_offset, np.asarray(model.rest_offsets)[lower],
                            rtol=0.0, atol=1e-12)
                and np.allclose(group.rest_rotation, np.asarray(model.rest_rotations)[lower],
                                rtol=0.0, atol=1e-12))
