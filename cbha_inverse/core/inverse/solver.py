"""
The per-tick inverse-simulation controller (paper Sec. IV, eq. 9-13; `docs/design.md`).

:class:`InverseSolver` holds the immutable model (chain, actuators, effectors, gravity) and a
mutable tick state (frame poses, current actuation, QP warm start). One :meth:`InverseSolver.step`:

1. linearise at the current state (:func:`cbha_inverse.core._kernels.evaluation.evaluate`, the
   static solver's evaluation too): tangent stiffness ``K`` (symmetric part of structure + load
   stiffness), actuator columns ``J_aᵀ`` and the residual ``r = f(q) + f_ext + J_aᵀ λ_prev``;
2. factor ``K = L Lᵀ`` (compiled block Cholesky) and sweep ``L⁻¹ [r, J_aᵀ]`` and ``L⁻¹ J_eᵀ``
   forward, giving ``W_ea``, ``W_aa`` and ``δ_e^free`` as products of these half-solves
   (:func:`cbha_inverse.core._kernels.projection.project_effectors_into`); if ``K`` is not
   positive definite, the fallback chain
   (:meth:`~cbha_inverse.core.system.EquilibriumSystem.fallback_factors`) solves
   ``K⁻¹ [r, J_aᵀ]`` and the same projection takes ``J_eᵀ`` and ``J_aᵀ`` as its left operands;
3. solve the regularised box QP (the exact active-set solver, compiled, and with obstacle rows
   an active set over the rows around it, ``docs/obstacles.md``; proxsuite, warm-started, or
   projected Gauss-Seidel on request or as fallbacks);
4. apply ``λ`` and update the state by the Newton step of the same factorization,
   ``dq = K⁻¹ r + K⁻¹ J_aᵀ (λ - λ_prev)`` (one backward sweep of one column,
   ``L⁻ᵀ (L⁻¹ r + L⁻¹ J_aᵀ Δλ)``), followed by ``newton_steps - 1``
   further full Newton steps at fixed ``λ`` if requested (or, with ``relinearize_every > 1``,
   keep the linear model for a few ticks; see :class:`InverseOptions`).

With the active-set QP and one Newton step per tick, a tick is one compiled call
(:func:`cbha_inverse.core._kernels.tick.control_tick`), on a prepared linearisation
(:meth:`InverseSolver.prepare`) or linearising first; the call stops before the QP when the
linearisation is off equilibrium or the trust region is narrowed (below), and the QP runs in
a call of its own after the check. The other paths (a clamped or rejected target, the fallback
chain, the QP solvers in Python, further Newton steps) call its parts.

Every linearisation measures the state's distance from equilibrium, ``|J_e K⁻¹ r|`` at the
effectors, narrows the actuation's step per tick (a trust region) when it exceeds
``equilibrium_tolerance``, and restores the equilibrium with the static solver when the Newton
updates diverge; a tick solved from a state off equilibrium reads ``'not_converged'``
(``docs/design.md``, "The state is an equilibrium, or the tick says it is not").

Repeated ticks therefore run Newton's method on the coupled problem (equilibrium plus optimal
actuation); at a fixed target the state converges to the static equilibrium of the returned
actuation. Each step is limited to ``max_rotation_step`` radians per frame so a far target cannot
throw the linearisation off.

The closed-loop :class:`~cbha_inverse.core.inverse.correction.TargetCorrector` lives in
:mod:`cbha_inverse.core.inverse.correction` (re-exported here).
"""

from dataclasses import replace
import math
import time

from cbha_inverse.core._kernels import tick as kernels
from cbha_inverse.core._kernels.projection import target_status, tick_outcome
from cbha_inverse.core._kernels.qp import SOLVED
from cbha_inverse.core._kernels.retraction import retract_frames
from cbha_inverse.core.actuation.effectors import TargetRefused
from cbha_inverse.core.chain import ChainState, external_wrenches, rest_state
from cbha_inverse.core.inverse.correction import TargetCorrector  # noqa: F401 (public re-export)
from cbha_inverse.core.inverse.obstacle_rows import (BINDING_TOLERANCE, checked_obstacles,
                                                     ObstacleRows, sphere_shares,
                                                     VIOLATION_TOLERANCE)
from cbha_inverse.core.inverse.qp import (ActiveSetQP, binding_bounds, projected_gauss_seidel,
                                          ProxsuiteQP, qp_problem, RowsQP)
from cbha_inverse.core.inverse.results import InverseOptions, TickResult
from cbha_inverse.core.inverse.tick_data import TickData
from cbha_inverse.core.inverse.touch import checked_touch, effector_index, TouchRows
from cbha_inverse.core.loads import dead_wrenches, follower_hooks, FollowerLoads, Loads
from cbha_inverse.core.sections import (check_section_factors, rate_limited,
                                        SectionStiffness)
from cbha_inverse.core.so3 import quat_from_matrix
from cbha_inverse.core.statics import solve_static
from cbha_inverse.core.system import EquilibriumSystem
import numpy as np

REACH_FACTOR = 2.0
"""Targets farther from the base than this many chain lengths are clamped onto that sphere."""
FAST_MOVE = 0.02
"""An actuator moving more than this fraction of its range ends a kept linearisation."""
MIN_TRUST_RADIUS = 1e-3
"""Smallest trust region of the actuation's step per tick, as a fraction of each range."""
TRUST_SHRINK = 0.5
"""Factor on the trust radius after a linearisation away from equilibrium."""
TRUST_GROW = 1.25
"""Factor on the trust radius after a linearisation well within the equilibrium tolerance."""
TRUST_GROW_BELOW = 0.25
"""The radius grows when the equilibrium gap is below this fraction of the tolerance."""
RESTORE_LOAD_STEPS = 16
"""Load steps the static solver may take to restore an equilibrium from rest."""
CONTRACTION = 0.5
"""A gap above the tolerance that the last tick's Newton update did not shrink below this
fraction of the one before: the updates diverge, and the static solver restores equilibrium."""
CHECKED_MOVE = 0.02
"""A tick moving an actuator by more than this fraction of its range checks its new state at once
(it linearises there, as :meth:`InverseSolver.prepare` would next)."""

ENTERING_ROUNDS = 4
"""Solves of a tick's QP at most: each after the first adds the obstacle rows of the spheres
the step before (moving an actuator by more than :data:`FAST_MOVE` of its range) would have
carried into an obstacle (:meth:`InverseSolver._entering`)."""

_NO_TURN = (math.nan, 0.0)
"""The orientation gap [rad, m] of a tick without rotational rows."""


class InverseSolver:
    """
    The per-tick controller of the module docstring (pure numerics, no ROS).

    Parameters
    ----------
    model : cbha_inverse.core.chain.ChainModel
        The frame chain.
    actuators : cbha_inverse.core.actuation.actuators.ActuatorSet
        Its actuators (``m``).
    effectors : cbha_inverse.core.actuation.effectors.PointEffectors
        Its effectors (``k``): points, and the orientation of the ``axis`` and ``pose``
        effectors' frames (``docs/effectors.md``; targets: :meth:`step`,
        :meth:`set_orientation_targets`).
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
    loads : cbha_inverse.core.loads.Loads, optional
        External loads in the model (:meth:`set_loads`; a scene's :attr:`loads`).
    obstacles : sequence of cbha_inverse.core.obstacles.Obstacle, optional
        Obstacles the collision spheres keep ``obstacle_margin`` from (:meth:`set_obstacles`,
        ``docs/obstacles.md``).
    collision : cbha_inverse.core.contact.CollisionSpheres, optional
        The robot's collision spheres (needed with obstacles).

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
        given ``scale`` is not positive and finite; on obstacles without collision spheres.

    Notes
    -----
    Every tick is overflow-safe: each effector target farther from the base than
    :data:`REACH_FACTOR` times the chain's length (plus the effector offset) is moved along the
    line from the base to it onto that sphere (no point beyond it is reachable, so the QP gives
    the same saturated answer), and a tick whose QP returns a non-finite actuation holds the
    last actuation and forgets the QP warm start (status ``'rejected'``), so the next sane
    target is tracked again without :meth:`reset`.

    The solver's state between ticks: whether the tick data hold a linearisation, how many ticks
    have used it (``relinearize_every``), whether :meth:`prepare` made it, and whether its
    linear step with the current actuation still waits to be applied to the frames (between
    linearisations). :meth:`_account` is the one place that updates it.

    """

    def __init__(self, model, actuators, effectors, gravity=None, options=None, scale=None,
                 sections=None, loads=None, obstacles=(), collision=None):
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
        self._rate = (None if self.options.rate_limit is None
                      else np.array(np.broadcast_to(np.asarray(self.options.rate_limit, float),
                                                    (m,))))
        self._span = span
        self._external = external_wrenches(model, gravity=gravity).reshape(-1)
        # the chain's own weight; the dead loads added (set_loads, set_payload); the payload
        # and the payload's acceleration (set_payload); the follower loads (set_loads)
        self._unloaded = self._external.copy()
        self._dead = self._external.copy()
        self._payload = 0.0
        self._gravity = None if gravity is None else np.asarray(gravity, dtype=float)
        self._loads, self._followers = Loads(), None
        # the links' stiffness the tick reads, scaled by the sections' factors
        self._sections = SectionStiffness(model.stiffnesses, sections or {})
        self.section_names = self._sections.names
        self._gains = np.ones(m)
        self.restorations = 0         # static solves that restored an equilibrium (or tried)
        self._scaled_model = None     # (section factors, the chain with their stiffness)
        self._system = EquilibriumSystem(model, actuators, self._external,
                                         stiffness=self._sections.stiffness)
        # no effector can be farther from the base than this (overflow-safe targets)
        self._base = np.array(model.base_position, dtype=float)
        offsets = np.asarray(effectors.offsets, dtype=float).reshape(-1, 3)
        self._reach = REACH_FACTOR * (model.length + np.linalg.norm(offsets, axis=1))
        self._active_set = ActiveSetQP(m)
        self._data = TickData(self._system, effectors, self._scale, self.lower_bounds,
                              self.upper_bounds, self._rate, self.options,
                              self._active_set.max_iterations, self._base, self._reach)
        self._active_set = ActiveSetQP(m, state=self._data.active_set)
        self._qp = ProxsuiteQP(m, eps_abs=self.options.eps_abs)
        self._target_shape = (effectors.n_effectors, 3)
        # whether some effector has rotational rows (a tick reports its orientation gap)
        self._turns = bool(effectors.orientation_effectors.size)
        self._every = self.options.relinearize_every
        # a tick on a prepared linearisation is one compiled call with the active set and one
        # Newton step per tick
        self._one_call = self._compiled_qp = (self.options.qp_solver == 'active_set'
                                              and self.options.newton_steps == 1)
        # the obstacle rows (set_obstacles): None without obstacles
        self._collision, self._obstacle_rows = collision, None
        self._rows_qp = RowsQP(m, eps_abs=self.options.eps_abs)
        # the contact targets (set_touch, docs/touch.md)
        self._touch = TouchRows(self._data, self.effector_names)
        # the plant's offset from the model at each effector (set_plant_offsets), and each
        # collision sphere's share of it
        self._plant_offsets = np.zeros((effectors.n_effectors, 3))
        self._sphere_shares = (None if collision is None
                               else sphere_shares(collision.frames, effectors.frames))
        self._control_tick = self._data.entry('control_tick')
        self._record = self._data.record
        # the frames and the actuation live in the tick data (the compiled tick updates them)
        self._positions, self._rotations = self._data.positions, self._data.rotations
        self.actuation = self._data.actuation
        if loads:
            self.set_loads(loads)
        if obstacles:
            self.set_obstacles(obstacles)
        self.reset()
        # until given, each orientation target is the effector's orientation at rest
        self._set_orientation_targets(effectors.directions(self._rotations),
                                      effectors.rotations(self._rotations))

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
        self._rows_qp.reset()
        self._active_set.reset()
        if self._obstacle_rows is not None:
            self._obstacle_rows.clear()
        self._linearised = False      # the tick data hold a valid linearisation
        self._residual_norm = math.nan
        self._gap = math.nan          # its effectors' distance from equilibrium [m]
        self._restored_gap = 0.0      # the gap before the static solver restored it [m]
        self._model_changed = False   # a payload, stiffness or gain changed since
        self._previous_gap = math.nan  # the gap of the linearisation before [m]
        self._set_trust_radius(self.options.max_step)
        self._pending = False         # its linear step with the current actuation is not applied
        self._age = 0                 # ticks that have used it
        self._prepared = False        # prepare() made it for the next tick

    def warm_up(self):
        """
        Run two ticks toward the current effector positions, then restore state and actuation.

        The first tick of a process compiles the numba kernels (or loads them from numba's
        on-disk cache); a node calls this before its control loop starts so that no control
        tick pays for it. The warm start of the QP is forgotten.
        """
        state, actuation = self.state, self.actuation.copy()
        targets = self.effector_positions()
        self.step(targets)
        self.prepare()
        self.step(targets)
        # the other paths: the fallback chain (each factor and its solve, the projection of
        # the first) and the pending step
        for factor in self._system.fallback_factors(self._positions, self._rotations,
                                                    self.actuation):
            factor.solve(np.zeros(self._system.size))
        self._fall_back()
        self._data.entry('pending_step_into')
        if self._obstacle_rows is not None:
            # the projection of the spheres' centres, whether or not a row is active now
            self._obstacle_rows.warm_up()
        self.reset(state, actuation)

    @property
    def state(self):
        """Return a copy of the current model frames as a ``ChainState``."""
        positions, rotations = self._current()
        return ChainState(positions.copy(), rotations.copy())

    def effector_positions(self):
        """Return the effector positions (k, 3) of the current model state."""
        return self.effectors.positions(*self._current())

    def effector_orientations(self):
        """
        Return the orientation of every effector's frame at the current model state.

        Returns
        -------
        (k, 4) ndarray
            Unit quaternions ``(x, y, z, w)`` (``w >= 0``), frame axes → world.

        """
        return quat_from_matrix(self.effectors.rotations(self._current()[1]))

    def effector_directions(self):
        """
        Return the world direction of every effector's axis at the current model state.

        Returns
        -------
        (k, 3) ndarray
            ``R_f u`` (``u`` the axis of an ``axis`` effector, ``+x`` for other kinds).

        """
        return self.effectors.directions(self._current()[1])

    def set_orientation_targets(self, directions=None, quaternions=None):
        """
        Set the orientation targets of the ``axis`` and ``pose`` effectors, validated.

        They hold for every later :meth:`step` until replaced (until first set: each effector's
        orientation at rest, the chain straight). ``docs/effectors.md`` gives the conventions.

        Parameters
        ----------
        directions : (a, 3) array_like, optional
            Target direction (world axes) of each ``axis`` effector, in effector order
            (``effectors.axis_effectors``); normalised; a zero or non-finite one is refused.
            ``(3,)`` for one. None: unchanged.
        quaternions : (p, 4) array_like, optional
            Target orientation (world axes, ``(x, y, z, w)`` as ROS) of each ``pose`` effector's
            frame, in effector order (``effectors.pose_effectors``); normalised when its norm
            is within :data:`~cbha_inverse.core.actuation.effectors.QUATERNION_TOLERANCE` of 1,
            else refused (and a non-finite one). ``(4,)`` for one. None: unchanged.

        Raises
        ------
        ValueError
            On a wrong shape, or a refused value
            (:class:`~cbha_inverse.core.actuation.effectors.TargetRefused`): nothing is changed.

        """
        checked_directions, checked_rotations = self.effectors.orientation_targets(
            directions, quaternions)
        self._set_orientation_targets(checked_directions, checked_rotations, by_kind=True)

    def _set_orientation_targets(self, directions, rotations, by_kind=False):
        """Write checked targets (per kind's effectors with ``by_kind``, else (k, ...))."""
        axis = list(self.effectors.axis_effectors) if by_kind else slice(None)
        pose = list(self.effectors.pose_effectors) if by_kind else slice(None)
        if directions is not None:
            self._data.target_directions[axis] = directions
        if rotations is not None:
            self._data.target_rotations[pose] = rotations

    @property
    def orientation_targets(self):
        """
        Return the current orientation targets (:meth:`set_orientation_targets`).

        Returns
        -------
        directions : (a, 3) ndarray
            Of the ``axis`` effectors, world axes.
        quaternions : (p, 4) ndarray
            Of the ``pose`` effectors, ``(x, y, z, w)``.

        """
        return (self._data.target_directions[list(self.effectors.axis_effectors)].copy(),
                quat_from_matrix(self._data.target_rotations[list(
                    self.effectors.pose_effectors)]).reshape(-1, 4))

    def _current(self):
        """Return the frames with the pending linear step applied (a copy when one is pending)."""
        if not self._pending:
            return self._positions, self._rotations
        positions, rotations = self._positions.copy(), self._rotations.copy()
        self._data.entry('pending_step_into')(self._record, positions, rotations)
        return positions, rotations

    def step(self, targets, directions=None, quaternions=None):
        """
        Run one control tick toward the effector targets.

        Parameters
        ----------
        targets : (k, 3) array_like  [m]
            Desired effector positions (world axes, effector order).
        directions : (a, 3) array_like, optional
            New target directions of the ``axis`` effectors (:meth:`set_orientation_targets`;
            None: the last ones set).
        quaternions : (p, 4) array_like, optional
            New target orientations ``(x, y, z, w)`` of the ``pose`` effectors
            (:meth:`set_orientation_targets`; None: the last ones set).

        Returns
        -------
        TickResult
            The new actuation, the updated effector positions, status and timings. A refused
            orientation target (not finite, a zero direction, a quaternion far from unit) holds
            the tick (status ``'rejected'``, the reason in ``warnings``) and keeps the previous
            orientation targets, as a non-finite position target does.

        Raises
        ------
        ValueError
            If ``targets`` does not have the shape (k, 3) (or (3,) for one effector): no other
            shape, e.g. a transposed (3, k) array, is reinterpreted; or an orientation target
            has the wrong shape.

        """
        started = time.perf_counter()
        targets = self._target_array(targets)
        if directions is not None or quaternions is not None:
            try:
                self.set_orientation_targets(directions, quaternions)
            except TargetRefused as exc:
                return self._held('rejected', started, warnings=(f'{exc}: rejected',))
        # the linearisation (steps 1-2) when no prepare() made it: checked for equilibrium
        # before the QP, as prepare() does
        fresh = not (self._linearised and self._age < self._every)
        if fresh and self._followers is not None:
            self._follow()
        if not self._one_call:
            if fresh and not self._prepare():
                return self._held('not_positive_definite', started)
            linearised = time.perf_counter() if fresh else started
            checked = target_status(targets, self._base, self._reach)
            if checked == 1:
                return self._held('rejected', started, warnings=('non-finite target rejected',))
            clamped, warnings = self._reachable(targets) if checked == 2 else (targets, ())
            if self._obstacle_rows is not None:
                warnings += self._obstacle_rows.inside_warnings(
                    self._touch.on_surface(clamped) if self._touch.touches else clamped)
            return self._split_tick(clamped, warnings, (started, linearised))
        code, iterations, largest_gap, largest_move, binding, residual_norm = self._control_tick(
            targets, self._record, fresh and self._pending, fresh, True, self._every == 1)
        # the obstacle rows' outcome of this solve, before a check of the new state relinearises
        obstacle = self._row_outcome()
        called = time.perf_counter()
        linearised = called if fresh else started
        if code in (kernels.TARGET_NOT_FINITE, kernels.BEYOND_REACH):
            # the call stopped at the target check: linearised and checked as by the parts
            if fresh and not self._prepare():
                return self._held('not_positive_definite', started)
            if code == kernels.TARGET_NOT_FINITE:
                return self._held('rejected', started,
                                  warnings=('non-finite target rejected',))
            clamped, warnings = self._reachable(targets)
            if self._obstacle_rows is not None:
                warnings += self._obstacle_rows.inside_warnings(clamped)
            return self._split_tick(clamped, warnings, (started, linearised))
        if fresh:
            # linearised in this call: checked as prepare() checks, the QP in a call of its own
            # when the check stopped the call before it
            stopped = code in (kernels.NOT_FACTORED, kernels.OFF_EQUILIBRIUM)
            if not self._checked_linearisation(self._linearised_by(code, residual_norm)):
                return self._held('not_positive_definite', started)
            if stopped:
                linearised = time.perf_counter()
                code, iterations, largest_gap, largest_move, binding, _ = self._control_tick(
                    targets, self._record, False, False, True, self._every == 1)
                called = time.perf_counter()
                obstacle = self._row_outcome()
        self._account()
        warnings = (() if self._obstacle_rows is None
                    else self._obstacle_rows.inside_warnings(targets))
        if code == SOLVED:
            return self._close(targets, 'saturated' if binding else 'solved', 'solved',
                               iterations, self._data.free.copy(), largest_gap, largest_move,
                               True, warnings, (started, linearised, called), obstacle)
        return self._after_active_set(code, targets, warnings, (started, linearised))

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
        return self._prepare()

    def _prepare(self, strict=False):
        """Linearise for the next tick unless the kept linearisation is valid (:meth:`prepare`)."""
        if self._linearised and self._age < self._every:
            return True
        return self._checked_linearisation(self._linearise_here(), strict)

    def _checked_linearisation(self, factored, strict=False):
        """Check a new linearisation (:meth:`_linearise`) and keep it for the next QP."""
        self._linearised = self._linearise(factored, strict)
        self._age, self._prepared = 0, self._linearised
        if self._obstacle_rows is not None and not self._linearised:
            # the rows are computed with every linearisation (the compiled projection's)
            self._obstacle_rows.clear()
        if self._linearised and self._touch.touches:
            self._touch.linearise()
        return self._linearised

    def _target_array(self, targets):
        """Return the targets as the compiled tick takes them, (k, 3) C-ordered floats."""
        targets = np.asarray(targets, dtype=float)
        if targets.shape != self._target_shape:
            if self._target_shape[0] == 1 and targets.shape == (3,):
                targets = targets.reshape(1, 3)
            else:
                raise ValueError(f'targets must have shape ({self._target_shape[0]}, 3), got '
                                 f'{targets.shape}')
        if not targets.flags.carray:
            # C-contiguous, aligned and writeable: the compiled entries take exactly this type
            targets = np.array(targets, order='C')
        return targets

    def _account(self):
        """Count a tick on the linearisation: the first after :meth:`prepare` is at age 1."""
        self._age = 1 if self._prepared else self._age + 1
        self._prepared = False

    def _linearise(self, factored, strict=False):
        """
        Check a linearisation at the stored state and actuation (steps 1-2) before its QP.

        ``factored``: whether the linearisation made by :meth:`_linearise_here` (or by a
        compiled tick that linearised, :meth:`_linearised_by`) factored, by the block Cholesky
        or the fallback chain (:meth:`_fall_back`). Its distance from equilibrium
        (:meth:`_measure_equilibrium`) adapts the trust region of the next steps
        (:meth:`_adapt_trust_region`); when the Newton updates diverge
        (:meth:`_diverging`), the static solver restores the equilibrium at the current
        actuation (:meth:`_restore_equilibrium`) and the linearisation is made again there
        (``_restored_gap`` keeps the distance it was at). With ``strict`` (after a large step,
        where the first-order gap can underestimate the distance several times over) it
        restores whenever the gap exceeds :data:`TRUST_GROW_BELOW` of the tolerance. Returns
        whether a factorization succeeded (the tick data then hold the linearisation).
        """
        self._restored_gap = 0.0
        if factored:
            self._adapt_trust_region(self._gap)
            restore = self._diverging() or (
                strict and self._gap > TRUST_GROW_BELOW * self.options.equilibrium_tolerance)
            if restore and self._restore_equilibrium():
                self._restored_gap = self._gap
                factored = self._linearise_here()
        return factored

    def _linearise_here(self):
        """
        Linearise, factor and project at the stored state and actuation; measure its gap.

        Applies a pending step first; the compiled linearisation, or, when its block Cholesky
        fails, the fallback chain. Returns whether a factorization succeeded.
        """
        if self._followers is not None:
            self._follow()
        code, _, _, _, _, residual_norm = self._control_tick(
            self._data.effector_positions, self._record, self._pending, True, False, False)
        return self._linearised_by(code, residual_norm)

    def _linearised_by(self, code, residual_norm):
        """
        Take the outcome of a compiled call that linearised (its pending step applied).

        ``code`` :data:`~cbha_inverse.core._kernels.tick.NOT_FACTORED`: the fallback chain
        (:meth:`_fall_back`) factors instead; any other code: the block Cholesky factored, and
        the linearisation's gap is measured. Returns whether a factorization succeeded.
        """
        self._pending = False
        if code == kernels.NOT_FACTORED:
            return self._fall_back()
        self._residual_norm = residual_norm
        self._measure_equilibrium()
        return True

    def _fall_back(self):
        """
        Factor and project the linearisation by the fallback chain (exact LU, then material).

        The residual is exact whatever the tangent, so only the convergence rate changes.
        Returns whether a factorization succeeded.
        """
        factor = next(self._system.fallback_factors(self._positions, self._rotations,
                                                    self.actuation), None)
        if factor is None:
            return False
        self._residual_norm = self._data.project_factor(factor)
        self._measure_equilibrium()
        return True

    def _split_tick(self, targets, warnings, times):
        """Run a tick whose target check and QP are calls of their own (module docstring)."""
        prepared = self._prepared
        self._account()
        return self._solve(targets, prepared, warnings, times)

    def _solve(self, targets, new_hessian, warnings, times):
        """Solve the QP of the tick data's linearisation and apply it (steps 3-4)."""
        if self.options.qp_solver != 'active_set' or self._touch.touches:
            return self._general_qp(targets, self.options.qp_solver, not new_hessian, warnings,
                                    times)
        code, iterations, largest_gap, largest_move, binding, _ = self._control_tick(
            targets, self._record, False, False, True, self._every == 1)
        if code == SOLVED:
            return self._close(targets, 'saturated' if binding else 'solved', 'solved',
                               iterations, self._data.free.copy(), largest_gap, largest_move,
                               True, warnings, times + (time.perf_counter(),),
                               self._row_outcome())
        return self._after_active_set(code, targets, warnings, times)

    def _after_active_set(self, code, targets, warnings, times):
        """
        Hold a non-finite QP solution, or hand an unconverged active set to proxsuite.

        With obstacle rows, proxsuite solves the rows QP (:meth:`_solve_rows`).
        """
        if code == kernels.REJECTED:
            return self._rejected('solved', warnings, times[0])
        # proxsuite (status checked) takes over; it has not seen this Hessian
        self._active_set.reset()
        return self._general_qp(targets, 'proxsuite', False, warnings, times)

    def _general_qp(self, targets, qp_solver, same_hessian, warnings, times):
        """Solve the tick's QP in Python (proxsuite, Gauss-Seidel) and apply it (steps 3-4)."""
        data = self._data
        if self._touch.touches:
            targets = self._touch.virtual_targets(targets)
        self._data.entry('free_gaps_of')(targets, self._record)
        delta_free = data.delta_free.copy()
        problem = qp_problem(data.matrices, delta_free, self.actuation, self.lower_bounds,
                             self.upper_bounds, rate_limit=self._step_limit())
        for _ in range(ENTERING_ROUNDS):
            if self._obstacle_rows_count() or self._touch.count:
                solution, status, obstacle = self._solve_rows(problem)
            else:
                solution, status = self._solve_qp(problem, qp_solver, same_hessian)
                obstacle = (0, math.nan, False)
            actuation, gap, largest_gap, largest_move, finite = tick_outcome(
                data.w_ea, delta_free, problem.scale, solution.x, problem.previous,
                self.lower_bounds, self.upper_bounds, targets.size)
            if not finite:
                return self._rejected(solution.status, warnings, times[0])
            if (self._obstacle_rows is None or largest_move <= FAST_MOVE
                    or not self._entering(actuation)):
                break
        saturated = binding_bounds(problem, solution.x)
        if status == 'solved' and saturated.any():
            status = 'saturated'
        self.actuation[:] = actuation
        data.gap[:] = gap
        if self._turns:
            data.entry('orientation_gap_of')(self._record)
        touch = None
        if self._touch.touches:
            touch = self._touch.outcome(actuation)
            warnings += touch[2]
        if self._every == 1:
            self._control_tick(targets, self._record, True, False, False, False)
        return self._close(targets, status, solution.status, solution.iterations, saturated,
                           largest_gap, largest_move, False, warnings,
                           times + (time.perf_counter(),), obstacle, touch)

    def _entering(self, actuation):
        """
        Return whether the step to ``actuation`` brings a sphere without a row into an obstacle.

        The step of the linearisation to ``actuation`` on copies of the frames; the pairs it
        carries within ``obstacle_margin`` get rows
        (:meth:`~cbha_inverse.core.inverse.obstacle_rows.ObstacleRows.add_entering`, the
        compiled tick's check), and the caller solves again.
        """
        return self._obstacle_rows.add_entering(actuation)

    def _row_outcome(self):
        """Return the compiled solve's rows, their largest violation [m], whether one binds."""
        if self._obstacle_rows is None:
            return (0, math.nan, False)
        return self._obstacle_rows.outcome()

    def _obstacle_rows_count(self):
        """Return the number of obstacle rows of the current linearisation (0 without)."""
        return 0 if self._obstacle_rows is None else self._obstacle_rows.count

    def _solve_rows(self, problem):
        """
        Solve the tick's QP with its obstacle rows and force rows (:class:`~.qp.RowsQP`).

        Returns ``(solution, status, (rows, violation, binding))``: the status ``'solved'`` or
        ``'qp_fallback'`` (proxsuite failed: the box QP without the rows, by Gauss-Seidel), the
        obstacle rows' largest predicted violation of the margin [m] and whether one binds.
        The force rows of the contact targets (:mod:`~.touch`) are stacked under the obstacle
        rows, which lose the rows of a touching sphere against the surface it touches.
        """
        data, options = self._data, self.options
        matrix, constant, obstacle_count = self._touch.stacked(self._obstacle_rows)
        # ν: the tracking term's normaliser (qp_hessians_into)
        normaliser = float(data.tracking_norm[0])
        solution, slack = self._rows_qp.solve(problem, matrix * self._scale, constant,
                                              normaliser, options.obstacle_weight)
        status = 'solved'
        if not solution.ok:
            status = 'qp_fallback'
            solution = projected_gauss_seidel(problem)
            solution = type(solution)(solution.x, f'gauss_seidel_{solution.status}', 0, True)
            slack = np.maximum(-(matrix @ (self._scale * solution.x) + constant), 0.0)
        clearances = (matrix[:obstacle_count] @ np.clip(self._scale * solution.x,
                                                        self.lower_bounds, self.upper_bounds)
                      + constant[:obstacle_count])
        if not obstacle_count:
            return solution, status, (0, math.nan, False)
        return solution, status, (obstacle_count, float(slack[:obstacle_count].max()),
                                  bool((clearances < BINDING_TOLERANCE).any()))

    def set_obstacles(self, obstacles):
        """
        Replace the obstacles the collision spheres keep clear of (``docs/obstacles.md``).

        Each linearisation then adds a row to the QP per (sphere, obstacle) pair within
        ``obstacle_activation`` of ``obstacle_margin``; the next tick relinearises. The rows
        and their QP run in the compiled tick; without obstacles it is the obstacle-free one.

        Parameters
        ----------
        obstacles : sequence of cbha_inverse.core.obstacles.Obstacle
            The obstacles (empty: none).

        Returns
        -------
        tuple of cbha_inverse.core.obstacles.Obstacle
            The obstacles now in the model.

        Raises
        ------
        ValueError
            If an item is not an ``Obstacle``, two share a name, or there are obstacles and the
            solver has no collision spheres: nothing is changed.

        """
        obstacles = checked_obstacles(obstacles)
        if obstacles and self._collision is None:
            raise ValueError("obstacles need collision spheres (a scene's collision block)")
        options = self.options
        if obstacles:
            self._obstacle_rows = ObstacleRows(
                self._collision, obstacles, options.obstacle_margin, options.obstacle_activation,
                self._data, options.obstacle_weight, FAST_MOVE, ENTERING_ROUNDS)
            self._obstacle_rows.set_shifts(self._sphere_shares @ self._plant_offsets)
        else:
            self._obstacle_rows = None
            self._data.attach_rows()
        self._rows_qp.reset()
        self._age = self._every
        self._linearised = False
        return obstacles

    def set_plant_offsets(self, offsets):
        """
        Tell the obstacle rows where the plant's effectors are measured from the model's.

        The closed loop holds the plant's effectors on their targets by asking the model for
        corrected targets: where the plant is softer or stiffer than the model, its arm lies
        away from the model's, and rows on the model's spheres would spend their margin on
        that model error. Given each effector's offset ``δ_e`` (plant minus model, e.g. minus
        the closed loop's correction), each collision sphere's centre is moved by its share of
        it before the distance query, ``(f_s / f_e) δ_e`` (``f`` the frame index: the offset
        grows from nothing at the base to ``δ_e`` at the effector's frame ``f_e``, the first
        effector at or beyond the sphere's frame; beyond the last effector its whole offset),
        so the rows keep the plant's spheres clear (``docs/obstacles.md``). The next
        linearisation uses them; they stay through :meth:`reset` and :meth:`set_obstacles`.

        Parameters
        ----------
        offsets : (k, 3) array_like  [m]
            Plant minus model position of every effector (zeros: the model's spheres).

        Raises
        ------
        ValueError
            If ``offsets`` is not (k, 3) or not finite: nothing is changed.

        """
        offsets = np.asarray(offsets, dtype=float)
        if offsets.shape != self._plant_offsets.shape:
            raise ValueError(f'plant offsets must have shape {self._plant_offsets.shape}, got '
                             f'{offsets.shape}')
        if not np.all(np.isfinite(offsets)):
            raise ValueError('plant offsets must be finite')
        self._plant_offsets[:] = offsets
        if self._obstacle_rows is not None:
            self._obstacle_rows.set_shifts(self._sphere_shares @ offsets)

    @property
    def obstacles(self):
        """Return the obstacles in the model (:meth:`set_obstacles`)."""
        return () if self._obstacle_rows is None else self._obstacle_rows.obstacles

    @property
    def obstacle_rows(self):
        """
        Return the obstacle rows of the current linearisation (None without obstacles).

        Returns
        -------
        cbha_inverse.core.inverse.obstacle_rows.ObstacleRows or None
            ``matrix`` ``G``, ``constant`` ``c``, ``names`` and ``frames`` of each row
            (read them; the solver rebuilds them at each linearisation).

        """
        return self._obstacle_rows

    def set_touch(self, effector, point, normal, force_bounds):
        """
        Give an effector a contact target: press a surface with bounded force (``docs/touch.md``).

        The effector's collision sphere is held against the surface through ``point`` with
        outward normal ``normal``, pressing along ``-normal`` with a force the model predicts
        within ``force_bounds`` (two rows of the QP, :mod:`cbha_inverse.core.inverse.touch`);
        its position target of :meth:`step` is followed in the surface's tangent plane only.
        It holds until :meth:`clear_touch`; the next tick relinearises.

        Parameters
        ----------
        effector : int or str
            The effector (index or name); its point must be its frame's origin, the centre of a
            collision sphere.
        point : (3,) array_like  [m]
            A point of the surface (world axes): where the sphere touches it.
        normal : (3,) array_like
            The surface's outward unit normal (out of the touched solid, toward the arm).
        force_bounds : (2,) array_like  [N]
            ``[f_min, f_max]``, ``0 <= f_min <= f_max``, finite.

        Returns
        -------
        cbha_inverse.core.inverse.touch.Touch
            The contact target now in the model.

        Raises
        ------
        ValueError
            On an unknown effector, one without a collision sphere at its point, a point or
            normal that is not finite, a normal not of unit length or invalid bounds: nothing
            is changed.

        """
        touch = checked_touch(self.effectors, self._collision, effector, point, normal,
                              force_bounds)
        self._touch.put(touch)
        self._one_call = False
        self._rows_qp.reset()
        self._age = self._every
        return touch

    def clear_touch(self, effector):
        """
        Drop an effector's contact target (:meth:`set_touch`): it tracks its target again.

        Parameters
        ----------
        effector : int or str
            The effector (index or name).

        Returns
        -------
        bool
            Whether it had one.

        Raises
        ------
        ValueError
            On an unknown effector.

        """
        cleared = self._touch.clear(effector_index(self.effector_names, effector))
        self._one_call = self._compiled_qp and not self._touch.touches
        self._rows_qp.reset()
        self._age = self._every
        return cleared

    @property
    def touches(self):
        """
        Return the contact targets (:meth:`set_touch`), by effector index.

        Returns
        -------
        dict of int to cbha_inverse.core.inverse.touch.Touch

        """
        return dict(self._touch.touches)

    @property
    def touch_rows(self):
        """
        Return the contact targets' force rows at the current linearisation (read them).

        Returns
        -------
        cbha_inverse.core.inverse.touch.TouchRows
            ``compliances`` ``c`` [m/N], ``rows()`` ``(G, b)`` [m] and ``outcome(λ)``, the
            predicted forces [N] (:mod:`cbha_inverse.core.inverse.touch`).

        """
        return self._touch

    def _solve_qp(self, problem, qp_solver, same_hessian):
        """
        Solve the tick's QP (step 3 of the module docstring) with the chosen solver and fallbacks.

        The active set falls back to proxsuite when it does not converge, proxsuite (status
        checked) to projected Gauss-Seidel. Returns ``(solution, status)``, the status
        ``'solved'`` or ``'qp_fallback'``.
        """
        status = 'solved'
        if qp_solver == 'active_set':
            solution = self._active_set.solve(problem)
            if solution.ok:
                return solution, status
            # proxsuite (status checked) takes over; it has not seen this Hessian
            qp_solver, same_hessian = 'proxsuite', False
        if qp_solver == 'proxsuite':
            solution = self._qp.solve(problem, same_hessian=same_hessian)
            if not solution.ok:
                status = 'qp_fallback'
                solution = projected_gauss_seidel(problem)
                solution = type(solution)(solution.x, f'gauss_seidel_{solution.status}', 0, True)
            return solution, status
        return projected_gauss_seidel(problem), status

    def _close(self, targets, status, qp_status, iterations, saturated, largest_gap,
               largest_move, positions_written, warnings, times, obstacle=(0, math.nan, False),
               touch=None):
        """
        Close a solved tick: Newton steps, effector positions, the result.

        ``positions_written``: the compiled tick wrote the effector positions into the tick
        data (of the new state, or between linearisations the linear model's prediction).
        ``times``: ``time.perf_counter()`` at the tick's start, after its linearisation and
        after its QP. ``obstacle``: the obstacle rows of the QP, their largest violation [m] and
        whether one binds (:meth:`_solve_rows`). ``touch``: the contact targets' predicted
        forces [N], how far they leave their bounds [N] and the warnings
        (:meth:`~cbha_inverse.core.inverse.touch.TouchRows.outcome`), or None without.
        """
        data = self._data
        # the distance from equilibrium of the state the tick solved from
        gap = max(self._gap, self._restored_gap)
        if self._age < self._every and largest_move > FAST_MOVE:
            # the actuation moves fast: the next tick relinearises
            self._age = self._every
        if self._every == 1:
            self._pending = False
            newton = self.options.newton_steps > 1
            for _ in range(self.options.newton_steps - 1):
                if not self._newton_step():
                    break
            if positions_written and not newton:
                effector_positions = data.effector_positions.copy()
            else:
                effector_positions = self.effectors.positions(self._positions, self._rotations)
        else:
            # between linearisations the tick is the linear model of paper eq. 11
            self._pending = True
            effector_positions = (data.effector_positions.copy() if positions_written
                                  else targets + data.gap[:targets.size].reshape(-1, 3))
        residual_norm = self._residual_norm
        turn, turn_length = (self._data.orientation_gap if self._turns else _NO_TURN)
        if status in ('solved', 'saturated'):
            if (self._every == 1 and largest_move > CHECKED_MOVE
                    and self.options.equilibrium_tolerance < math.inf
                    and self._prepare(strict=True)):
                # a large step may leave the linearisation's reach: check the new state now
                gap = max(gap, self._gap, self._restored_gap)
                if self._restored_gap:
                    effector_positions = self.effectors.positions(self._positions,
                                                                  self._rotations)
            status = self._tick_status(status, saturated, max(largest_gap, turn_length), gap,
                                       obstacle)
            if touch is not None and touch[1] > 0.0 and status in ('solved', 'saturated'):
                # the force bounds cannot hold: the surface or the force is out of reach
                status = 'unreachable'
        forces, force_violation = (None, math.nan) if touch is None else touch[:2]
        return TickResult(self.actuation.copy(), effector_positions, status, qp_status,
                          iterations, saturated, largest_gap, residual_norm,
                          _timings(*times, time.perf_counter()), warnings, gap, float(turn),
                          obstacle[0], obstacle[1], forces, force_violation)

    def _measure_equilibrium(self):
        """
        Take how far the linearised state is from equilibrium (``_gap`` [m]).

        The largest effector move of a Newton step at the current actuation, ``|J_e K⁻¹ r|``,
        is each effector's distance from the model's equilibrium to first order; the
        projection computed it (:func:`cbha_inverse.core._kernels.tick.equilibrium_gap_of`).
        """
        self._previous_gap, self._gap = self._gap, float(self._data.equilibrium_gap[0])

    def _diverging(self):
        """
        Return whether the state is off equilibrium and the Newton updates do not converge it.

        The gap is above ``equilibrium_tolerance`` and not below :data:`CONTRACTION` of the
        gap of the linearisation before (or there was none).
        """
        return self._gap > self.options.equilibrium_tolerance and not (
            self._gap <= CONTRACTION * self._previous_gap)

    def _restore_equilibrium(self):
        """
        Move the state to the model's equilibrium at the current actuation (paper eq. 9).

        The package's static solver (:func:`cbha_inverse.core.statics.solve_static`: the exact
        tangent, a line search, load steps if the warm start fails), warm-started from the
        current state, with the solver's loads (gravity, payload, :meth:`set_loads`: the
        follower loads with their load stiffness), its sections' stiffness and
        its actuator gains (a condensed cavity's wrench is linear in its pressure: gain ``g`` at
        ``p`` is the built cavity at ``g p``). Returns whether the state was restored.
        """
        function, tangent = follower_hooks(self._loads, self.model.n_links)
        result = solve_static(
            self._static_model(), frame_wrenches=self._dead.reshape(-1, 6),
            load_function=function, load_tangent=tangent,
            actuators=self.actuators, actuation=self.actuation * self._gains,
            initial_state=ChainState(self._positions.copy(), self._rotations.copy()),
            max_load_steps=RESTORE_LOAD_STEPS, check_warnings=False)
        self.restorations += 1
        if not result.converged:
            return False
        self._positions[:] = result.positions
        self._rotations[:] = result.rotations
        self._pending = False
        return True

    def _static_model(self):
        """Return the chain with the sections' stiffness of the tick (built once per factors)."""
        factors = tuple(self._sections.factors)
        if self._scaled_model is None or self._scaled_model[0] != factors:
            model = (self.model if all(f == 1.0 for f in factors)
                     else replace(self.model, stiffnesses=self._sections.stiffness.copy()))
            self._scaled_model = (factors, model)
        return self._scaled_model[1]

    def _adapt_trust_region(self, gap):
        """
        Narrow or widen the actuation's step per tick for an equilibrium gap ``gap`` [m].

        Each linearisation adapts it before the QP that solves on it (:meth:`_linearise`).

        A gap above ``equilibrium_tolerance`` after a tick's step means the step was more
        than the linearisation can follow: the radius is halved (down to
        :data:`MIN_TRUST_RADIUS` of each range), and with smaller steps each tick's Newton
        update converges the state again. A gap that follows a change of the model (a payload,
        the sections' stiffness, the actuators' gains) is the model's, not the step's: it is
        left to the Newton updates. Well within the tolerance (below
        :data:`TRUST_GROW_BELOW` of it) the radius grows back to ``max_step``.
        """
        tolerance = self.options.equilibrium_tolerance
        changed, self._model_changed = self._model_changed, False
        if gap > tolerance and not changed:
            self._set_trust_radius(max(TRUST_SHRINK * self._radius, MIN_TRUST_RADIUS))
        elif self._radius < self.options.max_step and gap < TRUST_GROW_BELOW * tolerance:
            self._set_trust_radius(min(TRUST_GROW * self._radius, self.options.max_step))

    def _set_trust_radius(self, radius):
        """
        Limit each actuator's change per tick to ``radius`` of its range (and the rate).

        A compiled tick that linearises runs its QP in the same call only where the check of
        the linearisation cannot change the radius (:meth:`_adapt_trust_region`): at
        ``max_step`` and a gap within ``equilibrium_tolerance`` (the tick data's
        ``gap_limit``); below ``max_step`` it always stops before the QP.
        """
        self._radius = radius
        rate = self._data.rate
        rate[:] = math.inf if self._rate is None else self._rate
        if radius < 1.0:
            np.minimum(rate, radius * self._span, out=rate)
        self._data.gap_limit[0] = (self.options.equilibrium_tolerance
                                   if radius >= self.options.max_step else -math.inf)

    def _step_limit(self):
        """Return the largest change per tick of each actuator, or None for none."""
        return None if self._rate is None and self._radius >= 1.0 else self._data.rate

    def _tick_status(self, status, saturated, largest_gap, gap, obstacle=(0, math.nan, False)):
        """
        Return a solved tick's status: ``'not_converged'``, ``'obstacle'`` or ``'unreachable'``.

        ``'not_converged'``: the tick's equilibrium ``gap`` (of the linearisation it solved on,
        or of its new state when it checked it) exceeds ``equilibrium_tolerance``.
        ``'obstacle'``: an obstacle row cannot hold (``obstacle``: the rows, their largest
        violation [m], whether one binds; :meth:`_solve_rows`).
        ``'unreachable'``: an actuator bound or an obstacle row holds the QP's optimum and the
        predicted gap exceeds ``unreachable_distance``. A tick held by the trust region alone
        reads ``'saturated'`` (a bound of its QP binds; the next ticks continue).
        """
        if gap > self.options.equilibrium_tolerance:
            return 'not_converged'
        _, violation, row_binds = obstacle
        if violation > VIOLATION_TOLERANCE:
            return 'obstacle'
        if row_binds and largest_gap > self.options.unreachable_distance:
            return 'unreachable'
        if status != 'saturated' or largest_gap <= self.options.unreachable_distance:
            return status
        margin = 1e-9 * self._span
        at_bound = (saturated & ((self.actuation <= self.lower_bounds + margin)
                                 | (self.actuation >= self.upper_bounds - margin))).any()
        return 'unreachable' if at_bound else status

    def _newton_step(self):
        """Apply one full Newton step at the current actuation; return whether it succeeded."""
        if self._followers is not None:
            self._follow()
        _, rhs = self._system.linearise(self._positions, self._rotations, self.actuation)
        factor = self._system.factor()
        if factor is None:
            return False
        step = factor.solve(rhs[:, :1])
        retract_frames(self._positions, self._rotations, step.reshape(-1, 6),
                       self.options.max_rotation_step, in_place=True)
        return True

    def _held(self, status, started, qp_status='not_run', warnings=()):
        """Return a tick result that keeps the actuation and the state."""
        m = self.actuation.size
        return TickResult(self.actuation.copy(), self.effector_positions(), status, qp_status, 0,
                          np.zeros(m, dtype=bool), math.nan, math.nan,
                          _timings(started, started, started, time.perf_counter()),
                          tuple(warnings))

    def _rejected(self, qp_status, warnings, started):
        """Hold after a non-finite QP solution and forget the warm starts."""
        # never a NaN actuation, never a poisoned warm start: hold, the next tick recovers
        self._qp.reset()
        self._active_set.reset()
        return self._held('rejected', started, qp_status,
                          warnings + ('QP returned a non-finite actuation: held',))

    def _reachable(self, targets):
        """
        Return the targets moved onto the reach sphere when beyond it, and the warnings.

        Parameters
        ----------
        targets : (k, 3) ndarray  [m]
            Finite effector targets.

        Returns
        -------
        targets : (k, 3) ndarray  [m]
        warnings : tuple of str

        """
        away = targets - self._base
        largest = np.abs(away).max(axis=1)
        far = largest > self._reach
        # direction without overflow: divide by the largest component before the norm
        unit = away[far] / largest[far, None]
        unit /= np.linalg.norm(unit, axis=1)[:, None]
        clamped = targets.copy()
        clamped[far] = self._base + self._reach[far, None] * unit
        names = ', '.join(name for name, f in zip(self.effector_names, far) if f)
        return clamped, (f'target of {names} is beyond any reach of the chain: clamped to '
                         f'{self._reach[far].max():.3g} m from the base',)

    # What the model takes from outside while it runs: a payload, the sections' stiffness, the
    # cavities' gains. Each replaces the previous value, comes rate-limited on request (an
    # estimated value should come in small steps: each change of the model is a step of the
    # commanded actuation, and in a loop on an estimate that step disturbs the estimate it came
    # from) and makes the next tick relinearise.

    def set_payload(self, mass, max_change=None):
        """
        Add a known mass at the last frame to the model's loads (e.g. an estimated payload).

        The tick's equilibrium then carries its weight (a load in ``f_ext`` of paper eq. 9, the
        same as a scene's ``tip_payload_mass``), so the QP compensates it in the model instead
        of leaving it to the closed loop's correction. It replaces the previous one; the next
        linearisation uses it (a node calls :meth:`prepare` right after, so that the target ->
        command path does not pay for it; an unchanged payload keeps the linearisation).

        Parameters
        ----------
        mass : float  [kg]
            The payload (0: none).
        max_change : float or None  [kg]
            Move the model's payload toward ``mass`` by at most this (None: all the way).

        Returns
        -------
        float  [kg]
            The payload now in the model's loads.

        Raises
        ------
        ValueError
            If ``mass`` is not finite, or the model has no gravity.

        """
        mass = float(mass)
        if not math.isfinite(mass):
            raise ValueError(f'payload must be finite, got {mass}')
        if self._gravity is None:
            raise ValueError('a payload needs the scene gravity')
        if max_change is not None:
            mass = self._payload + min(max(mass - self._payload, -max_change), max_change)
        if mass == self._payload:
            # the loads already carry it: the linearisation (prepared or not) stays valid
            return mass
        self._payload = mass
        self._set_dead()
        return mass

    @property
    def payload(self):
        """Return the payload in the model's loads [kg] (:meth:`set_payload`)."""
        return self._payload

    def set_loads(self, loads):
        """
        Replace the external loads in the model (``f_ext`` of paper eq. 9, ``docs/loads.md``).

        The dead wrenches and masses enter the constant loads the tick reads
        (:func:`cbha_inverse.core.loads.dead_wrenches`), as :meth:`set_payload` does; the next
        linearisation uses them, and unchanged loads keep the linearisation (the tick pays
        nothing). Follower wrenches (``axes='local'``) turn with their frame: each
        linearisation takes them at its state, without their load stiffness in the tick's
        tangent (the residual is exact, so the fixed point of the ticks is the loaded
        equilibrium; the static solver restoring it has their exact tangent). A payload of
        :meth:`set_payload` stays, on top of them.

        Parameters
        ----------
        loads : cbha_inverse.core.loads.Loads
            The loads (``Loads()``: none).

        Returns
        -------
        cbha_inverse.core.loads.Loads
            The loads now in the model.

        Raises
        ------
        ValueError
            If ``loads`` is not a ``Loads``, a load's frame lies beyond the chain, or a mass
            has no gravity.

        """
        if not isinstance(loads, Loads):
            raise ValueError(f'loads must be a Loads, got {type(loads).__name__}')
        loads.checked(self.model.n_links, self._gravity)
        if loads == self._loads:
            return loads
        self._loads = loads
        followers = FollowerLoads(loads, self.model.n_links)
        self._followers = followers if followers else None
        self._set_dead()
        return loads

    @property
    def loads(self):
        """Return the external loads in the model (:meth:`set_loads`)."""
        return self._loads

    def _set_dead(self):
        """Write the constant loads (weight, dead loads, payload) and make the tick relinearise."""
        dead = self._dead
        dead[:] = self._unloaded + dead_wrenches(self._loads, self.model.n_links,
                                                 self._gravity).reshape(-1)
        if self._payload:
            dead[-6:-3] += self._payload * self._gravity
        self._external[:] = dead
        if self._followers is not None:
            self._follow()
        self._model_changed = True
        self._age = self._every

    def _follow(self):
        """Turn the follower loads with the frames: the tick's loads at the current state."""
        np.add(self._dead, self._followers.wrenches(self._rotations).reshape(-1),
               out=self._external)

    def set_section_stiffness(self, factors, max_change=None):
        """
        Scale each chain section's link stiffness in the model (e.g. estimated factors).

        The links of section ``j`` become ``factors[j]`` times as stiff as the model's (as a
        scene's ``calibration.section_stiffness`` builds them), so the QP compensates a
        section's stiffness error in the model instead of leaving it to the closed loop's
        correction. It replaces the previous factors; the next linearisation uses them.

        Parameters
        ----------
        factors : (s,) array_like  [-]
            One factor per section, :attr:`section_names` order (1: the model's stiffness).
        max_change : float or None  [-]
            Move each factor toward ``factors`` by at most this (None: all the way).

        Returns
        -------
        (s,) ndarray  [-]
            The factors now in the model.

        Raises
        ------
        ValueError
            If ``factors`` is not one finite value per section within
            :data:`cbha_inverse.core.sections.SECTION_FACTOR_BOUNDS` (a model without
            sections takes none), or ``max_change`` is negative or not finite.

        """
        applied = self._sections.apply(factors, max_change)
        self._age = self._every
        self._model_changed = True
        return applied

    @property
    def section_stiffness(self):
        """Return the sections' stiffness factors in the model, (s,) [-]."""
        return self._sections.factors

    def set_actuator_gain(self, gains, max_change=None):
        """
        Scale each condensed cavity's effective area in the model (e.g. estimated gains).

        Cavity ``j`` then acts ``gains[j]`` times as strongly per Pa as the scene built it (as a
        scene's ``calibration.actuator_gain``); rate-limited and relinearised as
        :meth:`set_section_stiffness`.

        Parameters
        ----------
        gains : (m,) array_like  [-]
            One gain per actuator, :attr:`actuator_names` order (1: the scene's).
        max_change : float or None  [-]
            Move each gain toward ``gains`` by at most this (None: all the way).

        Returns
        -------
        (m,) ndarray  [-]
            The gains now in the model.

        Raises
        ------
        ValueError
            If ``gains`` is not one finite value per actuator within
            :data:`cbha_inverse.core.sections.SECTION_FACTOR_BOUNDS`, ``max_change`` is
            negative or not finite, or the actuators are not condensed cavities.

        """
        refused = check_section_factors(gains, self.actuation.size, 'actuator gain')
        if refused is not None:
            raise ValueError(refused[1])
        applied = rate_limited(self._gains, np.asarray(gains, dtype=float), max_change)
        self._system.scale_cavities(applied)
        self._gains = applied
        self._age = self._every
        self._model_changed = True
        return applied.copy()

    @property
    def actuator_gain(self):
        """Return the actuators' gains in the model, (m,) [-] (:meth:`set_actuator_gain`)."""
        return self._gains.copy()


def _timings(started, linearised, solved, ended):
    """
    Return a tick's timings [s] from ``time.perf_counter()`` at its phases' ends.

    ``assembly``: the linearisation (steps 1-2; 0 on a tick on a prepared or kept
    linearisation), ``qp``: the QP, its outcome and (active set) the Newton step, ``update``:
    further Newton steps, a check of the new state and the result, ``total``; ``factor`` and
    ``projection`` are 0 (they run inside the linearisation).
    """
    return {'assembly': linearised - started, 'factor': 0.0, 'projection': 0.0,
            'qp': solved - linearised, 'update': ended - solved, 'total': ended - started}
