"""
The compiled evaluation of the chain's equilibrium: residual, actuator columns and tangents.

:class:`EquilibriumSystem` is the one evaluator of paper eq. 9,
``r(q) = f(q) + f_ext + J_a(q)ᵀ λ``, behind the controller's tick
(:class:`cbha_inverse.core.inverse.solver.InverseSolver`), the static solver
(:func:`cbha_inverse.core.statics.solve_static`), the scenes' forward model and the simulated
plant. With the compiled kernels of :mod:`cbha_inverse.core._kernels`:

- one pass over the links gives the residual, the condensed cavities' columns and every link's
  exact 12 x 12 world tangent (paper eq. 8 with the geometric part and the exact cavity load
  stiffness), or its material part alone (:meth:`EquilibriumSystem.material_system`);
- one pass per cable group gives its columns, loads and span / point stiffness blocks;
- every block is added by a constant index into one of two band storages: the lower band of the
  symmetric part (weights ½ on the mirrored entries, the control tick's Cholesky,
  :meth:`EquilibriumSystem.linearise`), or the general band of the exact, non-symmetric tangent
  (Newton's LU, :meth:`EquilibriumSystem.exact_system`), with the half-bandwidth of the scene
  (cables that skip frames widen it).

Every factorisation returns a :class:`~cbha_inverse.core.linalg.factors.TangentFactor`, with
``solve(rhs)`` (multi-RHS) and ``method``: a band Cholesky factor of the symmetric or material
band (:meth:`EquilibriumSystem.factor`), a band LU factor of the exact band
(:meth:`EquilibriumSystem.factor_exact`), a dense LU of an exact tangent with a user load
stiffness. :meth:`EquilibriumSystem.fallback_factors` is the
one fallback chain (exact LU, then material Cholesky) of the control tick and of Newton's method.

Skinned-mesh cavities (:class:`~cbha_inverse.core.actuation.cavities.CavityGroup`, the exact
but slow cavity model) are evaluated through their own ``evaluate``; they couple every frame, so
the band is then the full matrix.
"""

from cbha_inverse.core._kernels.band import band_cholesky
from cbha_inverse.core._kernels.band_assembly import scatter_add
from cbha_inverse.core._kernels.cables import cable_work_size
from cbha_inverse.core._kernels.links import link_pass, link_work_size, nonzero_cavity_columns
from cbha_inverse.core.actuation.actuators import ActuatorSet
from cbha_inverse.core.actuation.cables import CableGroup, CableTerms
from cbha_inverse.core.actuation.condensed_cavities import LinearCavityGroup
from cbha_inverse.core.chain import rest_state
from cbha_inverse.core.linalg.factors import BandCholesky, BandLU, DenseLU
import numpy as np
from scipy.linalg import lapack


class EquilibriumSystem:
    """
    Preallocated compiled evaluator of the equilibrium of a chain and its actuators.

    Parameters
    ----------
    model : cbha_inverse.core.chain.ChainModel
        The chain.
    actuators : cbha_inverse.core.actuation.actuators.ActuatorSet
        The actuators (``m``).
    external : (6n,) ndarray  [N, N*m]
        Constant external wrenches on frames 1..n (gravity).
    stiffness : (n, 6, 6) ndarray, optional
        The links' stiffness the evaluations read (default: the model's); the shape
        estimator passes a read-only view of its own array, which it scales by its section
        stiffness unknowns before each linearisation.

    Attributes
    ----------
    kd : int
        Half-bandwidth of the tangent (11 for a chain whose actuators act within a link).
    tick_cholesky : bool
        The control tick's first choice is the band Cholesky of the symmetric tangent (default);
        False sends every tick to :meth:`fallback_factors` (the fallback chain's tests).

    """

    tick_cholesky = True

    def __init__(self, model, actuators, external, stiffness=None):
        """Precompute constants, buffers and the assembly index."""
        n = model.n_links
        m = actuators.n_actuators
        self.n, self.m, self.size = n, m, 6 * n
        self.stiffness = np.ascontiguousarray(model.stiffnesses if stiffness is None
                                              else stiffness, dtype=float)
        if self.stiffness.shape != (n, 6, 6):
            raise ValueError(f'stiffness must have shape ({n}, 6, 6), got '
                             f'{self.stiffness.shape}')
        self.rest_offsets = np.ascontiguousarray(model.rest_offsets, dtype=float)
        q0 = np.asarray(model.rest_rotations, dtype=float)
        identity = np.array_equal(q0, np.broadcast_to(np.eye(3), q0.shape))
        self._q0t = (np.zeros((0, 3, 3)) if identity
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
            elif isinstance(group, LinearCavityGroup):
                if not _matches_links(group, model):
                    raise ValueError(f'condensed cavities {group.names}: every part must lie on '
                                     'one link and carry its rest offset and rotation')
                for e in range(group.lower.size):
                    col = cols[group.owner[e]]
                    g0[group.lower[e], col] += group.g0[e]
                    hess[group.lower[e], col] += group.hessian[e]
                has_cavities = True
            else:
                self._generic.append((group, np.asarray(cols, dtype=int)))
        self.has_cavities = has_cavities
        # G0 and H of every actuator column per link (none without condensed cavities)
        self._cavity_wrench = g0 if has_cavities else np.zeros((n, 0, 6))
        self._cavity_stiffness = hess if has_cavities else np.zeros((n, 0, 6, 6))
        self._cavity_columns = nonzero_cavity_columns(self._cavity_wrench, self._cavity_stiffness)
        # the cavities as built, kept by the first scale_cavities (which overwrites them)
        self._built_cavities = None
        self._rhs = np.zeros((6 * n, m + 1))
        # values of the assembly: link blocks, cable pair blocks, cable point moments
        rows, cols = [], []
        f = np.arange(n)
        i12 = np.arange(12)
        link_dof = 6 * f[:, None] + i12[None, :] - 6          # frame a = l -> dof 6(l - 1)
        rows.append(np.broadcast_to(link_dof[:, :, None], (n, 12, 12)).reshape(-1))
        cols.append(np.broadcast_to(link_dof[:, None, :], (n, 12, 12)).reshape(-1))
        slices = []
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
            slices.append((slice(count, count + n_pair),
                           slice(count + n_pair, count + n_pair + n_mom)))
            count += n_pair + n_mom
        rows, cols = np.concatenate(rows), np.concatenate(cols)
        size = self.size
        valid = (rows >= 0) & (cols >= 0)
        lo, hi = np.minimum(rows, cols), np.maximum(rows, cols)
        self._weights = np.where(rows == cols, 1.0, 0.5)
        # lower band storage (entry (r, c) at [c, r - c] of a C-order (N, kd + 1) array, the
        # Fortran (kd + 1, N) layout of LAPACK); base-frame entries go to a trash row at the end,
        # value i to its slot i mod (kd + 1): consecutive values add into different slots (one
        # trash slot made the scatter wait on each add in turn, ~0.25 µs of the CBHA's 108)
        kd = size - 1 if self._generic else int((hi - lo)[valid].max())
        self.kd = kd
        self._index = np.where(valid, lo * (kd + 1) + hi - lo,
                               size * (kd + 1) + np.arange(rows.size) % (kd + 1))
        self._band = np.zeros((size + 1) * (kd + 1))
        # general band storage of the exact tangent for LAPACK's LU (dgbtrf, kl = ku = kd):
        # entry (r, c) at [c, 2 kd + r - c] of a C-order (N, 3 kd + 1) array
        width = 3 * kd + 1
        self._exact_index = np.where(valid, cols * width + 2 * kd + rows - cols, size * width)
        self._exact_band = np.zeros(size * width + 1)
        self._ones = np.ones(rows.size)
        self._exact_map = None            # dense <-> general band slots, on first use
        c, d = np.meshgrid(np.arange(size), np.arange(kd + 1), indexing='ij')
        inside = (c + d < size).reshape(-1)
        self._band_slots = np.flatnonzero(inside)
        self._dense_slots = ((c + d) * size + c).reshape(-1)[inside]
        self._values = np.zeros(count)
        self._link_values = self._values[:n * 144].reshape(n, 12, 12)
        self._cable_values = [(cab, self._values[p], self._values[q])
                              for cab, (p, q) in zip(self._cables, slices)]

    def evaluate(self, positions, rotations, actuation, material=False):
        """
        Run the compiled passes: residual, actuator columns and every tangent block.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations.
        actuation : (m,) ndarray  [N, Pa]
            ``λ`` (enters the residual and the load stiffness).
        material : bool
            Keep only the material tangent of the links (:meth:`material_system`).

        Returns
        -------
        rhs : (6n, m + 1) ndarray
            Column 0: the residual ``f(q) + f_ext + J_aᵀ λ``; columns 1..m:
            ``J_aᵀ``. A buffer of this object (overwritten by the next call).

        """
        positions = np.ascontiguousarray(positions, dtype=float)
        rotations = np.ascontiguousarray(rotations, dtype=float)
        actuation = np.ascontiguousarray(actuation, dtype=float)
        rhs = self._rhs
        link_pass(positions, rotations, self.stiffness, self.rest_offsets, self._q0t, actuation,
                  self._cavity_wrench, self._cavity_stiffness, self._cavity_columns, rhs,
                  self._link_values, material)
        for cab, pair_values, moment_values in self._cable_values:
            cab.evaluate(positions, rotations, actuation, rhs, pair_values, moment_values)
            if material:
                pair_values[:] = 0.0
                moment_values[:] = 0.0
        rhs[:, 0] += self.external
        for group, cols in self._generic:
            wrenches, _ = group.evaluate(positions, rotations, False)
            jat = wrenches[:, 1:, :].reshape(wrenches.shape[0], -1)
            rhs[:, 1 + cols] = jat.T
            rhs[:, 0] += actuation[cols] @ jat
        return rhs

    @property
    def rhs(self):
        """Return the (6n, m + 1) buffer that :meth:`evaluate` writes and returns."""
        return self._rhs

    def fused_terms(self):
        """
        Return the model arrays and buffers of the fused linearisation, or None.

        The fields ``stiffness`` ... ``rhs`` of the tick's buffers
        (:data:`cbha_inverse.core._kernels.tick_buffers.EVALUATION_FIELDS`), in their order
        (:func:`cbha_inverse.core._kernels.tick.linearise_tick` reads them): the constant
        terms of the links and of the cable group, the assembly index of the symmetric band and
        this object's buffers (so :meth:`fallback_factors` with ``evaluated=True`` reuses the
        blocks it leaves). ``None`` when the fused entry cannot evaluate the actuators (more
        than one cable group, or skinned-mesh cavities): the tick then runs :meth:`linearise`.

        Returns
        -------
        tuple of ndarray or None

        """
        if self._generic or len(self._cables) > 1:
            return None
        n_link = self.n * 144
        if self._cables:
            cab, pair_values, moment_values = self._cable_values[0]
            cable = (cab.gains, cab.offsets, cab.frames,
                     np.stack([cab.start, cab.end, cab.span_owner, cab.span_pair]),
                     np.stack([cab.point_owner, cab.point_slot]), cab.columns,
                     np.zeros(cable_work_size(cab.frames.size, cab.start.size,
                                              pair_values.size // 144)))
            counts = (n_link, pair_values.size, moment_values.size)
        else:
            empty = np.zeros(0, dtype=np.int64)
            cable = (np.zeros(0), np.zeros((0, 3)), empty, np.zeros((4, 0), dtype=np.int64),
                     np.zeros((2, 0), dtype=np.int64), empty, np.zeros(0))
            counts = (n_link, 0, 0)
        link_work = np.zeros(link_work_size(self._cavity_wrench.shape[1]))
        return ((self.stiffness, self.rest_offsets, self._q0t, self._cavity_wrench,
                 self._cavity_stiffness, self._cavity_columns, link_work,
                 np.ascontiguousarray(self.external))
                + cable
                + (self._index, self._weights, np.array(counts, dtype=np.int64), self._values,
                   self._band, self._rhs))

    def scale_cavities(self, gains):
        """
        Scale each condensed cavity's wrench and load stiffness by a gain, in place.

        The evaluations (and the fused tick, which holds the same arrays) then see cavity ``j``
        with ``gains[j]`` times the effective area it was built with, as a scene's
        ``calibration.actuator_gain`` builds it.

        Parameters
        ----------
        gains : (m,) ndarray  [-]
            Gain of each actuator relative to the built one (1: unchanged).

        Raises
        ------
        ValueError
            If the actuators are not condensed cavities, or ``gains`` does not have shape (m,).

        """
        if not self.has_cavities or self._generic or self._cables:
            raise ValueError('actuator gains need condensed cavities alone')
        gains = np.asarray(gains, dtype=float)
        if gains.shape != (self.m,):
            raise ValueError(f'gains must have shape ({self.m},), got {gains.shape}')
        if self._built_cavities is None:
            self._built_cavities = (self._cavity_wrench.copy(), self._cavity_stiffness.copy())
        wrench, stiffness = self._built_cavities
        np.multiply(wrench, gains[None, :, None], out=self._cavity_wrench)
        np.multiply(stiffness, gains[None, :, None, None], out=self._cavity_stiffness)

    def linearise(self, positions, rotations, actuation):
        """
        Return the symmetric tangent (lower band) and the right-hand sides of a tick.

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
        tangent : (6n, kd + 1) ndarray
            ``K`` (symmetric part of structure + load stiffness) in lower band storage,
            ``tangent[c, r - c] = K[r, c]`` (``c <= r``), for :meth:`factor`;
            :meth:`dense` converts it. A buffer of this object (overwritten by the next call).
        rhs : (6n, m + 1) ndarray
            As :meth:`evaluate`.

        """
        rhs = self.evaluate(positions, rotations, actuation)
        return self._symmetric_band(), rhs

    def material_system(self, positions, rotations, actuation):
        """
        Return the material tangent (lower band, SPD) and the right-hand sides.

        The links' ``Dᵀ Bᵀ K B D`` alone (paper eq. 8): no geometric part, no load stiffness,
        so it stays positive definite far from equilibrium (the fallback of a step whose
        exact tangent is singular or indefinite). Arguments and results as :meth:`linearise`.

        """
        rhs = self.evaluate(positions, rotations, actuation, material=True)
        return self._symmetric_band(), rhs

    def exact_system(self, positions, rotations, actuation):
        """
        Return the exact tangent (general band) and the right-hand sides.

        ``K = -d r / dq`` including the geometric part and the actuators' exact load stiffness
        (not symmetric): Newton's tangent (quadratic convergence). Arguments as
        :meth:`evaluate`.

        Returns
        -------
        tangent : (6n, 3 kd + 1) ndarray
            ``tangent[c, 2 kd + r - c] = K[r, c]`` for ``|r - c| <= kd``: the Fortran
            ``(3 kd + 1, N)`` layout of LAPACK's ``dgbtrf`` (rows ``0 .. kd - 1`` of that layout
            are its workspace), for :func:`factor_exact`; :meth:`dense_exact` converts it.
            A buffer of this object.
        rhs : (6n, m + 1) ndarray
            As :meth:`evaluate`.

        """
        rhs = self.evaluate(positions, rotations, actuation)
        return self.exact_tangent(), rhs

    def exact_tangent(self):
        """
        Return the exact tangent of the last :meth:`evaluate` (see :meth:`exact_system`).

        Returns
        -------
        (6n, 3 kd + 1) ndarray
            General band storage, a buffer of this object.

        """
        scatter_add(self._exact_index, self._values, self._ones, self._exact_band)
        return self._exact_band[:-1].reshape(self.size, 3 * self.kd + 1)

    def _symmetric_band(self):
        """Scatter the blocks of the last :meth:`evaluate` into the symmetric lower band."""
        scatter_add(self._index, self._values, self._weights, self._band)
        return self._band[:self.size * (self.kd + 1)].reshape(self.size, self.kd + 1)

    @staticmethod
    def factor(tangent):
        """
        Factor the tangent of :meth:`linearise` or :meth:`material_system` in place.

        Parameters
        ----------
        tangent : (6n, kd + 1) ndarray
            From :meth:`linearise` (overwritten by the factor).

        Returns
        -------
        BandCholesky or None
            The compiled band Cholesky factor; ``None`` if the tangent is not positive definite.

        """
        return BandCholesky(tangent) if band_cholesky(tangent) == 0 else None

    def dense_exact(self, tangent):
        """
        Return the general band storage of :meth:`exact_system` as a dense matrix.

        Parameters
        ----------
        tangent : (6n, 3 kd + 1) ndarray
            From :meth:`exact_system`.

        Returns
        -------
        (6n, 6n) ndarray

        """
        if self._exact_map is None:
            # entries (r, c), |r - c| <= kd: dense slot r N + c, band slot c (3 kd + 1) + 2 kd
            # + r - c; O(N kd) index arrays (a dense grid would be O(N^2) at every build)
            kd, size = self.kd, self.size
            c, offset = np.meshgrid(np.arange(size), np.arange(-kd, kd + 1), indexing='ij')
            r = c + offset
            inside = (r >= 0) & (r < size)
            self._exact_map = ((r * size + c)[inside],
                               (c * (3 * kd + 1) + 2 * kd + offset)[inside])
        dense_slots, band_slots = self._exact_map
        out = np.zeros((self.size, self.size))
        out.reshape(-1)[dense_slots] = np.asarray(tangent).reshape(-1)[band_slots]
        return out

    def factor_exact(self, tangent):
        """
        Factor the tangent of :meth:`exact_system` in place (LAPACK band LU, ``dgbtrf``).

        Parameters
        ----------
        tangent : (6n, 3 kd + 1) ndarray
            From :meth:`exact_system` (overwritten by the factor).

        Returns
        -------
        BandLU or None
            ``None`` if the tangent is singular or not finite.

        """
        if not np.all(np.isfinite(tangent)):
            return None
        lu, pivots, info = lapack.dgbtrf(tangent.T, self.kd, self.kd, overwrite_ab=1)
        return BandLU(lu, pivots, self.kd) if info == 0 else None

    def fallback_factors(self, positions, rotations, actuation, evaluated=False, load=None):
        """
        Yield the factors of the fallback chain, for a state whose first choice fails.

        The control tick's first choice is the Cholesky factor of the symmetric tangent
        (:meth:`linearise`), Newton's the exact tangent; when it fails (a tangent that is not
        positive definite at high pressures, a singular one near a limit point, a step that the
        line search rejects), the chain is, in this order:

        1. the exact tangent, structure + geometric part + exact load stiffness (not symmetric,
           :meth:`exact_system`), by band LU (:meth:`factor_exact`); with a user load stiffness
           ``load`` added, by dense LU;
        2. the material tangent alone (paper eq. 8, :meth:`material_system`), positive definite
           whatever the stresses, far from equilibrium too, by band Cholesky (:meth:`factor`).

        The residual is the same for every tangent (only the convergence rate changes). A
        tangent that does not factor is skipped. The evaluation of step 2 overwrites this
        object's buffers (those of the last :meth:`evaluate`).

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations.
        actuation : (m,) ndarray  [N, Pa]
            ``λ`` (enters the load stiffness).
        evaluated : bool
            The last :meth:`evaluate` (not material) was at this state and actuation: step 1
            reuses its blocks.
        load : (6n, 6n) ndarray or None  [N/m, N, N*m/rad]
            Load stiffness ``-d f_load / dq`` of user follower loads, added to the exact tangent.

        Yields
        ------
        cbha_inverse.core.linalg.factors.TangentFactor
            Each factor that succeeds (``BandLU`` or ``DenseLU``, then ``BandCholesky``).

        """
        if not evaluated:
            self.evaluate(positions, rotations, actuation)
        tangent = self.exact_tangent()
        if load is None:
            factor = self.factor_exact(tangent)
        else:
            factor = DenseLU(self.dense_exact(tangent) + load)
        if factor is not None:
            yield factor
        tangent, _ = self.material_system(positions, rotations, actuation)
        factor = self.factor(tangent)
        if factor is not None:
            yield factor

    def blocks(self, tangent):
        """
        Return the lower band of :meth:`linearise` as block-tridiagonal blocks.

        Parameters
        ----------
        tangent : (6n, 12) ndarray
            From :meth:`linearise` of a chain whose actuators act within a link.

        Returns
        -------
        diagonal : (n, 6, 6) ndarray
            Diagonal blocks.
        upper : (n - 1, 6, 6) ndarray
            ``upper[i]`` = block (i, i + 1).

        """
        if self.kd != 11:
            raise ValueError(f'the tangent is not block tridiagonal (half-bandwidth {self.kd})')
        band = np.asarray(tangent).reshape(self.n, 6, 12)
        a, b = np.meshgrid(np.arange(6), np.arange(6), indexing='ij')
        low, high = np.minimum(a, b), np.maximum(a, b)
        diagonal = band[:, low, high - low]
        upper = band[:-1, a, 6 + b - a]
        return diagonal, upper

    def dense(self, tangent):
        """
        Return the band storage of :meth:`linearise` as a full lower-triangular matrix.

        Parameters
        ----------
        tangent : (6n, kd + 1) ndarray
            From :meth:`linearise`.

        Returns
        -------
        (6n, 6n) ndarray
            ``K`` on and below the diagonal, zero above.

        """
        out = np.zeros((self.size, self.size))
        out.reshape(-1)[self._dense_slots] = np.asarray(tangent).reshape(-1)[self._band_slots]
        return out


def chain_stiffness(model, state=None):
    """
    Return the symmetric tangent stiffness of a bare chain over frames 1..n (dense).

    Parameters
    ----------
    model : cbha_inverse.core.chain.ChainModel
        The chain.
    state : cbha_inverse.core.chain.ChainState, optional
        Frame poses (default: the rest shape, where the tangent is the assembled ``K`` of the
        links, paper eq. 8).

    Returns
    -------
    (6n, 6n) ndarray  [N/m, N, N*m/rad]

    """
    state = rest_state(model) if state is None else state
    system = EquilibriumSystem(model, ActuatorSet((), model.n_frames), np.zeros(6 * model.n_links))
    tangent, _ = system.linearise(state.positions, state.rotations, np.zeros(0))
    lower = system.dense(tangent)
    return lower + np.tril(lower, -1).T


def _matches_links(group, model):
    """Whether every condensed cavity part has the rest geometry of its link."""
    lower = group.lower
    if lower.size == 0 or lower.min() < 0 or lower.max() >= model.n_links:
        return False
    return bool(np.allclose(group.rest_offset, np.asarray(model.rest_offsets)[lower],
                            rtol=0.0, atol=1e-12)
                and np.allclose(group.rest_rotation, np.asarray(model.rest_rotations)[lower],
                                rtol=0.0, atol=1e-12))
