"""
The per-tick inverse-simulation controller (paper Sec. IV, eq. 9-13; `docs/design.md`).

:class:`InverseSolver` holds the immutable model (chain, actuators, effectors, gravity) and a
mutable tick state (frame poses, current actuation, QP warm start). One :meth:`InverseSolver.step`:

1. linearise at the current state in one fused pass of the compiled kernels
   (:class:`cbha_inverse.core.system.EquilibriumSystem`, the static solver's evaluation too):
   tangent stiffness ``K`` (symmetric part of structure + load stiffness), actuator columns
   ``J_aᵀ`` and the residual ``r = f(q) + f_ext + J_aᵀ λ_prev``;
2. factor ``K = L Lᵀ`` (compiled band Cholesky) and sweep ``L⁻¹ [r, J_aᵀ]`` and ``L⁻¹ J_eᵀ``
   forward, giving ``W_ea``, ``W_aa`` and ``δ_e^free`` as products of these half-solves
   (:func:`cbha_inverse.core._kernels.projection.project_effectors_into`); if ``K`` is not
   positive definite, the fallback chain
   (:meth:`~cbha_inverse.core.system.EquilibriumSystem.fallback_factors`) solves
   ``K⁻¹ [r, J_aᵀ]`` and the same projection takes ``J_eᵀ`` and ``J_aᵀ`` as its left operands;
3. solve the regularised box QP (proxsuite, warm-started, or the exact active-set solver; projected
   Gauss-Seidel on request or as a fallback if proxsuite reports a failure);
4. apply ``λ`` and update the state by the Newton step of the same factorization,
   ``dq = K⁻¹ r + K⁻¹ J_aᵀ (λ - λ_prev)`` (one backward sweep of one column,
   ``L⁻ᵀ (L⁻¹ r + L⁻¹ J_aᵀ Δλ)``), followed by ``newton_steps - 1``
   further full Newton steps at fixed ``λ`` if requested (or, with ``relinearize_every > 1``,
   keep the linear model for a few ticks; see :class:`InverseOptions`).

The closed-loop :class:`~cbha_inverse.core.inverse.correction.TargetCorrector` lives in
:mod:`cbha_inverse.core.inverse.correction` (re-exported here).

Repeated ticks therefore run Newton's method on the coupled problem (equilibrium plus optimal
actuation); at a fixed target the state converges to the static equilibrium of the returned
actuation. Each step is limited to ``max_rotation_step`` radians per frame so a far target cannot
throw the linearisation off.
"""

import math
import time

from cbha_inverse.core._kernels import tick as fused
from cbha_inverse.core._kernels.projection import target_status
from cbha_inverse.core._kernels.qp import SOLVED
from cbha_inverse.core._kernels.retraction import retract_frames
from cbha_inverse.core.chain import ChainState, external_wrenches, rest_state
from cbha_inverse.core.inverse.correction import TargetCorrector  # noqa: F401 (public re-export)
from cbha_inverse.core.inverse.model_terms import ModelTerms
from cbha_inverse.core.inverse.qp import ActiveSetQP, ProxsuiteQP
from cbha_inverse.core.inverse.results import InverseOptions, TickResult
from cbha_inverse.core.inverse.tick_data import TickData
from cbha_inverse.core.inverse.tick_paths import FAST_MOVE, TickPaths
from cbha_inverse.core.sections import SectionStiffness
from cbha_inverse.core.system import EquilibriumSystem
import numpy as np

# targets farther from the base than this many chain lengths are clamped onto that sphere
_REACH_FACTOR = 2.0
# the tick's globals, one lookup each
_perf_counter = time.perf_counter
_asarray = np.asarray
_FLOAT = np.dtype(float)


class InverseSolver(TickPaths, ModelTerms):
    """
    The per-tick controller of the module docstring (pure numerics, no ROS).

    Parameters
    ----------
    model : cbha_inverse.core.chain.ChainModel
        The frame chain.
    actuators : cbha_inverse.core.actuation.actuators.ActuatorSet
        Its actuators (``m``).
    effectors : cbha_inverse.core.actuation.effectors.PointEffectors
        Its effector points (``k``).
    gravity : (3,) array_like or None  [m/s^2]
        Gravity acting on the lumped masses.
    options : InverseOptions, optional
        Solver options.
    scale : (m,) array_like, optional
        Actuator scales ``σ`` (default: ``upper - lower``; an actuator with zero range is
        fixed at its bound and scaled like the widest one, see :attr:`warnings`).
    sections : dict, optional
        The chain's sections, ``name -> (first link index, count)`` in chain order
        (:attr:`cbha_inverse.scene.scene.Scene.section_links`): their stiffness factors can be
        set (:meth:`set_section_stiffness`).

    Attributes
    ----------
    warnings : tuple of str
        What the user should know about the set-up (zero-range actuators); a node logs them.
    section_names : tuple of str
        The sections of ``sections`` (empty without).

    Raises
    ------
    ValueError
        If an actuator has no finite upper bound, a lower bound above its upper bound, or a
        given ``scale`` is not positive and finite.

    Notes
    -----
    Every tick is overflow-safe: each effector target farther from the base than
    ``_REACH_FACTOR`` times the chain's length (plus the effector offset) is moved along the
    line from the base to it onto that sphere (no point beyond it is reachable, so the QP gives
    the same saturated answer), and a tick whose QP returns a non-finite actuation holds the
    last actuation and forgets the QP warm start (status ``'rejected'``), so the next sane
    target is tracked again without :meth:`reset`.

    """

    def __init__(self, model, actuators, effectors, gravity=None, options=None, scale=None,
                 sections=None):
        """Precompute the constant parts and start from rest."""
        self.model = model
        self.actuators = actuators
        self.effectors = effectors
        self.options = options or InverseOptions()
        self.lower_bounds = np.array(actuators.lower_bounds, dtype=float)
        self.upper_bounds = np.array(actuators.upper_bounds, dtype=float)
        if not np.all(np.isfinite(self.upper_bounds)):
            raise ValueError('every actuator needs a finite upper bound')
        self.actuator_names = tuple(actuators.names)
        self.effector_names = tuple(effectors.names)
        m = actuators.n_actuators
        span = self.upper_bounds - self.lower_bounds
        inverted = [name for name, width in zip(self.actuator_names, span) if not width >= 0.0]
        if inverted:
            raise ValueError(f'actuator {inverted[0]!r}: lower bound above the upper bound')
        fixed = [name for name, width in zip(self.actuator_names, span) if width == 0.0]
        self.warnings = tuple(f'actuator {name!r} has zero range: fixed at its bound'
                              for name in fixed)
        if scale is None:
            # a zero-range actuator's x = λ/σ is fixed by its bounds whatever σ: any positive σ
            self._scale = np.where(span > 0.0, span, span.max() if span.max() > 0.0 else 1.0)
        else:
            self._scale = np.array(scale, dtype=float)
            if self._scale.shape != (m,) or not np.all(np.isfinite(self._scale)) or np.any(
                    self._scale <= 0.0):
                raise ValueError(f'scale must be {m} positive finite values')
        # a plain C-order copy: one compiled signature of the QP kernels whatever was given
        self._rate = (None if self.options.rate_limit is None
                      else np.array(np.broadcast_to(np.asarray(self.options.rate_limit, float),
                                                    (m,))))
        self._external = external_wrenches(model, gravity=gravity).reshape(-1)
        # the model's loads without a payload, and the payload's acceleration (set_payload)
        self._unloaded = self._external.copy()
        self._payload = 0.0
        self._gravity = None if gravity is None else np.asarray(gravity, dtype=float)
        # the links' stiffness the tick reads, scaled by the sections' factors
        self._sections = SectionStiffness(model.stiffnesses, sections or {})
        self.section_names = self._sections.names
        self._gains = np.ones(m)
        self._tick = EquilibriumSystem(model, actuators, self._external,
                                       stiffness=self._sections.stiffness)
        self._effector_frames = np.ascontiguousarray(effectors.frames, dtype=np.int64)
        self._effector_offsets = np.ascontiguousarray(effectors.offsets, dtype=float)
        # no effector can be farther from the base than this (overflow-safe targets)
        self._base = np.array(model.base_position, dtype=float)
        self._reach = _REACH_FACTOR * (model.length + np.linalg.norm(
            self._effector_offsets, axis=1))
        self._active_set = ActiveSetQP(m)
        self._data = TickData(self._tick, effectors, self._scale, self.lower_bounds,
                              self.upper_bounds, self._rate, self.options,
                              self._active_set.max_iterations, self._base, self._reach)
        self._active_set = ActiveSetQP(m, state=self._data.state)
        self._qp = ProxsuiteQP(m, eps_abs=self.options.eps_abs)
        self._m, self._k = m, effectors.n_effectors
        self._target_shape = (self._k, 3)
        self._max_rotation = self._data.max_rotation
        # the compiled check without numba's per-call dispatch (step passes (k, 3) C floats)
        self._target_status = fused.compiled_entry(target_status, self._data.effector_positions,
                                                   self._base, self._reach)
        # the whole tick as one compiled call (fused linearisation, active set, one Newton
        # step per tick); otherwise the target check, the linearisation and the QP one by one
        self._buffers = self._data.buffers
        self._every = self.options.relinearize_every
        self._apply_step = self._every == 1
        self._tick_entry = (self._data.tick_entry if self._data.fused
                            and self.options.qp_solver == 'active_set'
                            and self.options.newton_steps == 1 else None)
        # the frames and the actuation live in the tick data (the compiled tick updates them)
        self._positions, self._rotations = self._data.positions, self._data.rotations
        self.actuation = self._data.actuation
        self.reset()

    def reset(self, state=None, actuation=None):
        """
        Return to rest (or to a given state and actuation) and forget the warm start.

        Parameters
        ----------
        state : cbha_inverse.core.chain.ChainState, optional
            Start state (default: the rest shape; the first ticks then settle it under gravity).
        actuation : (m,) array_like, optional
            Start actuation (default: zero, clipped to the bounds).

        """
        state = rest_state(self.model) if state is None else state
        self._positions[:] = state.positions
        self._rotations[:] = state.rotations
        a = np.zeros(len(self.actuator_names)) if actuation is None else actuation
        self.actuation[:] = np.clip(np.asarray(a, dtype=float), self.lower_bounds,
                                    self.upper_bounds)
        self._qp.reset()
        self._active_set.reset()
        self._linearised = False      # the tick data holds a valid linearisation
        self._residual_norm = math.nan
        self._pending = False         # its linear step with the current actuation is not applied
        self._age = 0
        self._prepared = False

    def warm_up(self):
        """
        Run two ticks toward the current effector positions, then restore state and actuation.

        The first tick of a process compiles the numba kernels (or loads them from numba's
        on-disk cache, ~0.3 s); a node calls this before its control loop starts so that no
        control tick pays for it. The warm start of the QP is forgotten.
        """
        state, actuation = self.state, self.actuation.copy()
        targets = self.effector_positions()
        self.step(targets)
        self.prepare()
        self.step(targets)
        # the compiled projection that follows a fallback factorization (reset forgets it)
        fused.project_tick(self._data.buffers)
        # the entries of the ticks that leave the one compiled call (a target beyond reach, a
        # failed band Cholesky, prepare), compiled or loaded, not run
        for entry in ('linearise_entry', 'solve_entry', 'step_entry'):
            getattr(self._data, entry)
        # the pending step on copies of the frames (state and effector positions between
        # linearisations, ``relinearize_every`` > 1)
        self._data.pending_entry(self._data.buffers, self._positions.copy(),
                                 self._rotations.copy())
        self.reset(state, actuation)

    def _current(self):
        """Return the frames with the pending linear step applied (a copy when one is pending)."""
        if not self._pending:
            return self._positions, self._rotations
        positions, rotations = self._positions.copy(), self._rotations.copy()
        self._data.pending_entry(self._data.buffers, positions, rotations)
        return positions, rotations

    def _materialise(self):
        """Apply the pending linear step to the stored frames."""
        if self._pending:
            self._data.step_entry(self._data.buffers)
            self._pending = False

    @property
    def state(self):
        """Return a copy of the current model frames as a ``ChainState``."""
        positions, rotations = self._current()
        return ChainState(positions.copy(), rotations.copy())

    def effector_positions(self):
        """Return the effector positions (k, 3) of the current model state."""
        return self.effectors.positions(*self._current())

    def step(self, targets):
        """
        Run one control tick toward the effector targets.

        Parameters
        ----------
        targets : (k, 3) array_like  [m]
            Desired effector positions (world axes, effector order).

        Returns
        -------
        TickResult
            The new actuation, the updated effector positions, status and timings.

        Raises
        ------
        ValueError
            If ``targets`` does not have the shape (k, 3) (or (3,) for one effector): no other
            shape, e.g. a transposed (3, k) array, is reinterpreted.

        """
        t_start = _perf_counter()
        targets = _asarray(targets, _FLOAT)
        if targets.shape != self._target_shape:
            if self._k == 1 and targets.shape == (3,):
                targets = targets.reshape(1, 3)
            else:
                raise ValueError(f'targets must have shape ({self._k}, 3), got {targets.shape}')
        if not targets.flags.carray:
            # C-contiguous, aligned and writeable: the compiled entries take exactly this type
            # (they do not check it)
            targets = np.array(targets, order='C')
        tick = self._tick_entry
        if tick is None:
            checked = self._target_status(targets, self._base, self._reach)
            if checked == 1:
                return self._held('rejected', t_start, warnings=('non-finite target rejected',))
            return self._step(targets, checked, t_start)
        # the whole tick in one compiled call: the target check, the linearisation (when due)
        # and the active-set QP with its step
        fresh = not self._linearised or self._age >= self._every
        code, iterations, largest_gap, largest_move, binding, residual_norm = tick(
            targets, self._buffers, fresh and self._pending, fresh, self._tick.tick_cholesky,
            self._apply_step)
        if code != SOLVED:
            return self._after_tick(code, targets, fresh, residual_norm, t_start)
        if fresh:
            self._linearised, self._residual_norm, self._age = True, residual_norm, 1
        else:
            self._age = 1 if self._prepared else self._age + 1
        self._prepared = False
        every = self._every
        if self._age < every and largest_move > FAST_MOVE:
            # the actuation moves fast: the next tick relinearises
            self._age = every
        # between linearisations the tick is the linear model of paper eq. 11
        self._pending = every != 1
        data = self._data
        actuation, effector_positions = data.actuation.copy(), data.effector_positions.copy()
        saturated = data.mask.copy()
        total = _perf_counter() - t_start
        # one compiled call: its time is the linearisation's (when it linearised) or the QP's
        timings = {'assembly': total if fresh else 0.0, 'factor': 0.0, 'projection': 0.0,
                   'qp': 0.0 if fresh else total, 'update': 0.0, 'total': total}
        return TickResult.of_tick(actuation, effector_positions,
                                  'saturated' if binding else 'solved', 'solved', iterations,
                                  saturated, largest_gap, self._residual_norm, timings, ())

    def prepare(self):
        """
        Linearise now for the next :meth:`step`, off the target-to-command path.

        A node calls it right after publishing a command: the next ``step`` then only solves the
        QP and applies it (steps 3-4 of the module docstring), so the target-to-command latency
        excludes the linearisation (steps 1-2). The state and actuation do not change in
        between, so the result is exactly that of linearising inside the next step. Does nothing
        while the current linearisation is still valid (``relinearize_every`` > 1).

        Returns
        -------
        bool
            False when no factorization of the tangent succeeds (the next step then holds).

        """
        if self._linearised and self._age < self.options.relinearize_every:
            return True
        self._materialise()
        self._linearised = self._linearise()
        self._age, self._prepared = 0, self._linearised
        return self._linearised

    def _linearise(self):
        """
        Linearise, factor and project at the stored state and actuation (steps 1-2).

        One compiled entry (:func:`cbha_inverse.core._kernels.tick.linearise_tick`) when the
        scene allows it; when the band Cholesky fails (or the scene's actuators need the
        general evaluation), the fallback chain (:meth:`_fall_back`). Returns whether a
        factorization succeeded (the tick data then holds the linearisation).
        """
        data = self._data
        if data.fused:
            info, residual_norm = data.linearise_entry(data.buffers, self._tick.tick_cholesky)
            if info == 0:
                self._residual_norm = residual_norm
                return True
        return self._fall_back()

    def _fall_back(self):
        """
        Factor and project the linearisation without the fused band Cholesky.

        After a failed fused Cholesky (the evaluation is written), the fallback chain
        (:meth:`~cbha_inverse.core.system.EquilibriumSystem.fallback_factors`: exact LU, then
        material Cholesky) and the compiled projection
        (:func:`~cbha_inverse.core._kernels.tick.project_tick`); for a scene whose actuators
        need the general evaluation, that evaluation and its band Cholesky first. Returns
        whether a factorization succeeded.
        """
        data, system = self._data, self._tick
        factor = None
        if not data.fused:
            tangent, _ = system.linearise(self._positions, self._rotations, self.actuation)
            data.linearised[:] = self.actuation
            if system.tick_cholesky:
                factor = system.factor(tangent)
        if factor is None:
            # not positive definite: the fallback chain (exact LU, then material Cholesky) of
            # the same evaluation; the residual is exact in every case, so only the
            # convergence rate changes
            factor = next(system.fallback_factors(self._positions, self._rotations,
                                                  self.actuation, evaluated=True), None)
        if factor is None:
            return False
        self._residual_norm = data.project_factor(factor)
        return True

    def _newton_step(self):
        """Apply one full Newton step at the current actuation; return whether it succeeded."""
        tangent, rhs = self._tick.linearise(self._positions, self._rotations, self.actuation)
        factor = self._tick.factor(tangent)
        if factor is None:
            return False
        step = factor.solve(rhs[:, :1])
        retract_frames(self._positions, self._rotations, step.reshape(-1, 6),
                       self.options.max_rotation_step, in_place=True)
        return True
