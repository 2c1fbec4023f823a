"""
Quasi-static equilibrium of a frame chain under loads and actuation (paper eq. 9).

:func:`solve_static` is the package's one solver of eq. 9, behind the scenes' forward model
(:meth:`cbha_inverse.scene.Scene.forward`) and the simulated plant
(:class:`cbha_inverse.sim.plant.StaticPlant`). It solves, for the poses of frames 1..n,

    r(q) = f(q) + lam (f_dead + J_a(q)ᵀ λ + f_load(q)) = 0

with ``f`` the internal wrenches, ``f_dead`` constant world wrenches (tip, frame wrenches,
gravity: :func:`cbha_inverse.core.chain.external_wrenches`), ``J_a(q)ᵀ λ`` the actuators'
configuration-dependent (follower) wrenches, ``f_load`` optional user follower loads and ``lam``
the load factor. The residual and every tangent come from the compiled kernels the control tick
runs (:class:`cbha_inverse.core.system.EquilibriumSystem`), so the controller, the statics and
the plant evaluate the same physics with the same code:

- Newton increments ``dq = T⁻¹ r`` (world axes, as for :func:`cbha_inverse.core.chain.retract`)
  with ``T = -dr/dq`` the exact, non-symmetric tangent: material + geometric part of the links
  and the actuators' exact load stiffness (quadratic convergence; the structural tangent alone
  sees a tendon-compressed backbone as unstable), factored by the compiled block LU of its
  6 x 6 frame blocks (:mod:`cbha_inverse.core._kernels.block_lu`, O(n)). If the tangent is
  singular, the step is not finite or the line search rejects it, the iteration falls back to
  the material tangent (paper eq. 8, SPD whatever the stresses, compiled block Cholesky): a
  modified-Newton step, robust where ``T`` is indefinite or singular (a chain near a limit
  point, high pressure). Both come from the one fallback chain of the package,
  :meth:`cbha_inverse.core.system.EquilibriumSystem.fallback_factors`;
- the increment is applied in the chain's deformation coordinates
  (:func:`cbha_inverse.core._kernels.retraction.deformation_step`): full Newton steps stay
  acceptable at large rotations of slender chains (the PL^2/EI = 10 elastica converges from rest
  in one load step of 7 iterations);
- backtracking line search on the Euclidean norm of the scaled residual (Armijo, factor 1/2),
  optionally starting from a step shortened so that no link turns by more than
  ``max_rotation_step``, and shortened to the fraction ``load_step_limit`` allows (the step up
  to a contact that begins: a penalty's tangent is blind to a contact until it begins, so the
  full step would pass through the obstacle and the search would creep up to it from outside);
- load stepping: a warm start (``initial_state``) is tried at the full load first; otherwise or
  if it fails, the full load from the rest shape; a load step that fails (no convergence within
  ``max_iterations`` or a failed line search) is halved, successful steps double the increment.

Convergence test (``residual_norm`` reports the left-hand side), by default relative. Forces
and moments are compared in one unit: ``r_scaled`` is the residual with moments divided by the
chain length L_c (so both parts are in N), and the force and moment parts of the applied loads
and of the internal wrenches give one ``load_scale`` (the largest scaled component of either),
so a pure moment load judges the force residual against it and vice versa. A state converges:

1. if every component is finite and ``max |r_scaled| <= tolerance * load_scale``; or
2. (round-off limited) if every frame's residual is within ``tolerance * load_scale + floor_i``
   and the Newton correction from that state moves no frame by more than
   ``_ROUNDOFF_STEP * x_ref`` (1e-8) nor turns one by more than ``_ROUNDOFF_STEP`` rad: the
   correction is applied (unless it is below ``1000 eps``, i.e. noise) and the corrected state
   is returned. ``floor_i`` is the round-off level of the internal wrench at frame i,
   ``64 eps max(|K_tt| x_ref + |K_tr|, (|K_rt| x_ref + |K_rr|) / L_c)`` over the (at most two)
   links meeting at frame i, with ``x_ref = L_c + |base position|`` (max-abs entries of their
   stiffness blocks). A near-rigid link (compliance / 1e9) has forces
   that no double-precision state resolves below its floor, so its frames can only converge
   this way; the floor of one stiff link never lets the residual of other frames pass, and the
   rest state under a small load never passes (its correction is the deflection). The result
   then carries a warning when the residual is large against the applied load.

A non-finite residual never converges. With ``absolute_tolerance`` the test is instead
``|r|_2 <= absolute_tolerance`` (unscaled Euclidean norm in N and N*m, the plant's contract).

The converged state is checked for what the user should know (:attr:`StaticResult.warnings`,
:mod:`cbha_inverse.core.static_warnings`): a round-off limited residual, an unstable
equilibrium, links strained beyond the small-strain range of their compliance.
"""

from dataclasses import dataclass
from types import SimpleNamespace
from typing import NamedTuple
import weakref

from cbha_inverse.core._kernels import newton
from cbha_inverse.core._kernels.records import compiled_entry, make_record
from cbha_inverse.core._kernels.retraction import deformation_step, deformed_poses
from cbha_inverse.core.actuation.actuators import ActuatorSet
from cbha_inverse.core.chain import ChainState, checked_array, external_wrenches, rest_state
from cbha_inverse.core.static_warnings import (roundoff_warnings, stability_warnings,
                                               strain_warnings)
from cbha_inverse.core.system import EquilibriumSystem
import numpy as np

_ARMIJO = 1e-4
_MAX_HALVINGS = 6
_MIN_LOAD_INCREMENT = 1.0 / 2 ** 20
# round-off limited convergence: a Newton correction below sqrt(eps) of the chain's size is
# applied and ends the iteration; one below 1000 eps is noise and is not even applied
_ROUNDOFF_STEP = 1e-8
_ROUNDOFF_NOISE = 1e3 * np.finfo(float).eps


class StaticConvergenceError(RuntimeError):
    """A static solve did not converge (raised only by strict solves); ``.result`` holds it."""

    def __init__(self, result):
        super().__init__(result.message)
        self.result = result


@dataclass(frozen=True, eq=False)
class StaticResult:
    """
    Result of :func:`solve_static`: an equilibrium of paper eq. 9, or why none was reached.

    Attributes
    ----------
    positions : (n + 1, 3) ndarray  [m]
        Frame origins, frame 0 = base.
    quaternions : (n + 1, 4) ndarray
        Frame orientations (x, y, z, w).
    rotations : (n + 1, 3, 3) ndarray
        Frame rotation matrices.
    state : ChainState
        The same poses as a state (e.g. to warm-start the next solve).
    converged : bool
        True only if the full load was reached and the convergence test passed.
    iterations : int
        Total Newton iterations over all load steps.
    residual_norm : float  [N]
        Convergence measure (see the module docstring) of the returned state under the full
        load.
    residual : (n, 6) ndarray  [N, N*m]
        The residual ``r`` of the returned state under the full load.
    load_steps : int
        Load steps attempted (successful and failed; a warm start counts as one).
    load_factor : float
        Fraction of the load in equilibrium at the returned state (1.0 when converged).
    message : str
        What happened, in words.
    actuation : (m,) ndarray  [N or Pa]
        The applied actuation (empty without actuators).
    effector_positions : (k, 3) ndarray  [m]
        The effector points at the returned state ((0, 3) without effectors).
    warnings : tuple of str
        What the user should know about a converged state: round-off limited residual, an
        unstable equilibrium (buckling), links strained beyond their small-strain range
        (module docstring).

    Notes
    -----
    If not converged, the state is the last equilibrium at ``load_factor`` < 1, or (when no
    load step succeeded after a warm start) the warm start's last iterate.

    """

    positions: np.ndarray
    quaternions: np.ndarray
    rotations: np.ndarray
    state: ChainState
    converged: bool
    iterations: int
    residual_norm: float
    residual: np.ndarray
    load_steps: int
    load_factor: float
    message: str
    actuation: np.ndarray
    effector_positions: np.ndarray
    warnings: tuple = ()


def _residual_floor(model, length):
    """
    Round-off level of the scaled internal wrench at each of frames 1..n (module docstring).

    Returns
    -------
    (n,) ndarray  [N]

    """
    k = np.abs(model.stiffnesses)
    k_tt = k[:, :3, :3].max(axis=(1, 2))
    k_tr = np.maximum(k[:, :3, 3:].max(axis=(1, 2)), k[:, 3:, :3].max(axis=(1, 2)))
    k_rr = k[:, 3:, 3:].max(axis=(1, 2))
    x_ref = length + float(np.linalg.norm(model.base_position))
    per_link = 64.0 * np.finfo(float).eps * np.maximum(k_tt * x_ref + k_tr,
                                                       (k_tr * x_ref + k_rr) / length)
    # frame j (1..n) is the end of link j - 1 and the start of link j
    per_frame = per_link.copy()
    per_frame[:-1] = np.maximum(per_frame[:-1], per_link[1:])
    return per_frame


_SYSTEMS = weakref.WeakKeyDictionary()
_ENTRIES = {}


class _ChainConstants(NamedTuple):
    """What every static problem of one chain model uses (computed once per model)."""

    length: float              # characteristic length L_c [m] (1 for a zero-length chain)
    x_ref: float               # L_c + |base position| [m]
    floor: np.ndarray          # (n,) round-off floor per frame [N]
    rest_rotations: np.ndarray  # (n, 3, 3) Q0, C order
    rest: ChainState           # the rest shape (never modified)


def _cached(model):
    """Return the per-model cache entry (systems, Newton buffers and constants)."""
    entry = _SYSTEMS.get(model)
    if entry is None:
        length = model.length if model.length > 0.0 else 1.0
        constants = _ChainConstants(
            length, length + float(np.linalg.norm(model.base_position)),
            np.ascontiguousarray(_residual_floor(model, length)),
            np.ascontiguousarray(model.rest_rotations, dtype=float), rest_state(model))
        entry = {'chain': None, 'actuated': weakref.WeakKeyDictionary(),
                 'newton': weakref.WeakKeyDictionary(), 'constants': constants}
        _SYSTEMS[model] = entry
    return entry


def _newton_record(model, actuators, system):
    """Return the Newton buffers of a chain and its actuators, built once per pair."""
    per_model = _cached(model)
    records = per_model['newton']
    key = 'chain' if actuators is None else actuators
    if key == 'chain':
        record = per_model.get('chain_newton')
    else:
        record = records.get(actuators)
    if record is None:
        constants = per_model['constants']
        n, m = model.n_links, system.m
        arrays = {'actuation': np.zeros(m), 'scaled_actuation': np.zeros(m),
                  'dead': np.zeros(6 * n), 'extra': np.zeros(6 * n), 'floor': constants.floor,
                  'frame_max': np.zeros(n), 'residual': np.zeros(6 * n),
                  'step': np.zeros((6 * n, 1)), 'rest_rotations': constants.rest_rotations,
                  'coordinates': np.zeros((n, 12))}
        record = SimpleNamespace(record=make_record(
            newton.NewtonRecord, newton.new_newton_record, system=system.record, **arrays),
            **arrays)
        if key == 'chain':
            per_model['chain_newton'] = record
        else:
            records[actuators] = record
    return record


def _entries(record, state):
    """
    Return the compiled kernels of a Newton iteration, by name (built once per process).

    ``'point'`` (:func:`~cbha_inverse.core._kernels.newton.newton_point`), ``'trial'``
    (:func:`~cbha_inverse.core._kernels.newton.newton_trial`), ``'direction'``
    (:func:`~cbha_inverse.core._kernels.newton.newton_direction`) and ``'coordinates'``
    (:func:`~cbha_inverse.core._kernels.retraction.deformation_step`), called without numba's
    per-call type dispatch (:func:`cbha_inverse.core._kernels.records.compiled_entry`): every
    record has one type, and :class:`_Problem` passes C-ordered float arrays of fixed
    dimensions and float scalars.
    """
    if not _ENTRIES:
        positions, rotations = state.positions.copy(), state.rotations.copy()
        _ENTRIES['point'] = compiled_entry(newton.newton_point, record.record, positions,
                                           rotations, 1.0, 1.0, 1e-10)
        _ENTRIES['trial'] = compiled_entry(newton.newton_trial, record.record, positions,
                                           rotations, 1.0, positions, rotations, 1.0, 1.0, 1e-10)
        _ENTRIES['direction'] = compiled_entry(newton.newton_direction, record.record, positions,
                                               rotations)
        _ENTRIES['coordinates'] = compiled_entry(deformation_step, positions, rotations,
                                                 record.record.rest_rotations,
                                                 np.zeros((record.frame_max.size, 6)),
                                                 record.coordinates)
    return _ENTRIES


def _system(model, actuators):
    """
    Return the compiled evaluator of a chain and its actuators, built once per pair.

    Its constant external wrenches are zero: the static problem adds its own dead loads.
    """
    per_model = _cached(model)
    if actuators is None:
        if per_model['chain'] is None:
            per_model['chain'] = EquilibriumSystem(model, ActuatorSet((), model.n_frames),
                                                   np.zeros(6 * model.n_links))
        return per_model['chain']
    system = per_model['actuated'].get(actuators)
    if system is None:
        system = EquilibriumSystem(model, actuators, np.zeros(6 * model.n_links))
        per_model['actuated'][actuators] = system
    return system


class _Point(NamedTuple):
    """A state evaluated at a load factor."""

    state: ChainState
    residual: np.ndarray   # (n, 6) r
    measure: float         # convergence measure (module docstring)
    norm: float            # line-search merit (scaled residual above the round-off floors)
    converged: bool        # test 1 of the module docstring (or the absolute test)
    roundoff: bool         # the residual part of test 2 (the caller checks the correction)
    load_scale: float      # largest scaled applied or internal wrench component [N]


class _Problem:
    """One static problem: compiled evaluator, loads, convergence test and tangent solves."""

    def __init__(self, model, actuators, actuation, external, load_function, load_tangent,
                 tolerance, absolute_tolerance, max_rotation_step, load_step_limit=None):
        self.model = model
        self.system = _system(model, actuators)
        self.newton = _newton_record(model, actuators, self.system)
        self.actuation = actuation
        self.newton.actuation[:] = actuation
        self.external = self.newton.dead
        self.external[:] = np.asarray(external, dtype=float).reshape(-1)
        self.newton.extra[:] = 0.0
        self.load_function = load_function
        self.load_tangent = load_tangent
        self.tolerance = float(tolerance)
        self.absolute = None if absolute_tolerance is None else float(absolute_tolerance)
        self.max_rotation_step = max_rotation_step
        self.load_step_limit = load_step_limit
        constants = _cached(model)['constants']
        self.length, self.x_ref = constants.length, constants.x_ref
        # the record's read-only view: the compiled kernels see one type of it
        self.rest_rotations, self.rest = self.newton.record.rest_rotations, constants.rest
        self.coordinates = self.newton.coordinates
        self._evaluated = None
        self._entries = _entries(self.newton, self.rest)

    def point(self, state, lam):
        """Evaluate a state at load factor ``lam`` (residual, convergence test)."""
        self._set_extra(state)
        measures = self._entries['point'](
            self.newton.record, np.ascontiguousarray(state.positions, dtype=float),
            np.ascontiguousarray(state.rotations, dtype=float), float(lam), self.length,
            self.tolerance)
        return self._measured(state, lam, measures)

    def trial(self, state, alpha, lam):
        """
        Evaluate ``state`` moved along the last step's deformation coordinates by ``alpha``.

        The line search's point (:func:`~cbha_inverse.core._kernels.newton.newton_trial`); a
        user load function is evaluated at the moved state.
        """
        if self.load_function is not None:
            return self.point(self.poses(state, alpha), lam)
        positions, rotations = np.empty_like(state.positions), np.empty_like(state.rotations)
        measures = self._entries['trial'](
            self.newton.record, np.ascontiguousarray(state.positions, dtype=float),
            np.ascontiguousarray(state.rotations, dtype=float), float(alpha), positions,
            rotations, float(lam), self.length, self.tolerance)
        return self._measured(ChainState(positions, rotations), lam, measures)

    def _set_extra(self, state):
        """Write the user loads at ``state`` into the record (none without a load function)."""
        if self.load_function is None:
            return
        n = self.model.n_links
        extra = np.asarray(self.load_function(state), dtype=float)
        if extra.shape != (n, 6):
            raise ValueError(f'load_function must return shape {(n, 6)}')
        self.newton.extra[:] = extra.reshape(-1)

    def _measured(self, state, lam, measures):
        """Return the point of an evaluated state (its blocks are the system's now)."""
        measure, merit, scaled_norm, norm, scale, within = measures
        self._evaluated = (state, lam)
        residual = self.newton.residual.reshape(-1, 6).copy()
        if self.absolute is not None:
            return _Point(state, residual, norm, scaled_norm, norm <= self.absolute, False,
                          scale)
        return _Point(state, residual, measure, merit, measure <= self.tolerance * scale,
                      within, scale)

    def roundoff_step(self, step, relative):
        """Return whether a Newton correction (n, 6) is below ``relative`` (module docstring)."""
        return bool(np.abs(step[:, :3]).max() <= relative * self.x_ref
                    and np.abs(step[:, 3:]).max() <= relative)

    def coordinates_of(self, state, step=None):
        """Return the links' deformation coordinates ``(u, φ, du, dφ)`` (n, 12) for a step."""
        step = np.zeros((self.model.n_links, 6)) if step is None else step
        largest = self._entries['coordinates'](
            np.ascontiguousarray(state.positions, dtype=float),
            np.ascontiguousarray(state.rotations, dtype=float), self.rest_rotations,
            np.ascontiguousarray(step, dtype=float), self.coordinates)
        return self.coordinates, largest

    def steps(self, point, lam):
        """
        Yield Newton's steps at a point by the tangents of the fallback chain, in order.

        The exact tangent (with the user load stiffness, if any), then the material one
        (:meth:`cbha_inverse.core.system.EquilibriumSystem.fallback_factors`). The exact step of
        the point just evaluated, without user loads, is one compiled call
        (:func:`~cbha_inverse.core._kernels.newton.newton_direction`), which leaves its
        deformation coordinates ready for the line search.

        Yields
        ------
        step : (n, 6) ndarray or None  [m, rad]
            The step, or None when this tangent gave none.
        why : str
            Which tangent, or why it gave no step.
        link_rotation : float or None  [rad]
            The largest link rotation of the step when its coordinates are ready, else None.

        """
        state = point.state
        evaluated = self._evaluated == (state, lam)
        tried = evaluated and self.load_tangent is None
        if tried:
            info, largest = self._entries['direction'](
                self.newton.record, np.ascontiguousarray(state.positions, dtype=float),
                np.ascontiguousarray(state.rotations, dtype=float))
            if info == 0:
                yield self.newton.step.reshape(-1, 6).copy(), 'block_lu', largest
            else:
                yield None, 'singular exact tangent', None
        load = None if self.load_tangent is None or lam == 0.0 else self.load_tangent(state)
        if load is not None:
            load = lam * np.asarray(load, dtype=float)
        for factor in self.system.fallback_factors(state.positions, state.rotations,
                                                   lam * self.actuation, evaluated, load,
                                                   exact=not tried):
            # the chain may have evaluated the system again (material tangent): forget the key
            self._evaluated = None
            try:
                step = factor.solve(point.residual.reshape(-1)).reshape(-1, 6)
            except np.linalg.LinAlgError as exc:
                yield None, str(exc) or 'singular tangent', None
                continue
            yield step, factor.method, None
        self._evaluated = None

    def applied(self, state):
        """Return the applied loads (n, 6) at ``state`` under the full load [N, N*m]."""
        rhs = self.system.evaluate(state.positions, state.rotations, self.actuation)
        self._evaluated = None
        applied = (rhs[:, 1:] @ self.actuation + self.external).reshape(-1, 6)
        if self.load_function is not None:
            applied = applied + np.asarray(self.load_function(state), dtype=float)
        return applied

    def first_alpha(self, link_rotation):
        """Return the first line-search step: no link turns by more than the limit."""
        limit = self.max_rotation_step
        if limit is None or link_rotation <= limit:
            return 1.0
        return limit / link_rotation

    def poses(self, state, alpha):
        """Return the state of the last step's deformation coordinates advanced by ``alpha``."""
        positions, rotations = state.positions.copy(), state.rotations.copy()
        deformed_poses(self.coordinates, alpha, self.rest_rotations, positions, rotations)
        return ChainState(positions, rotations)


def _line_search(problem, point, lam, step, link_rotation=None):
    """
    Backtrack along the Newton step (in deformation coordinates) on the residual norm.

    Armijo test on the Euclidean norm of the scaled residual above the round-off floor of each
    frame (module docstring; the plain scaled norm with an absolute tolerance),
    ``|r(a)| <= (1 - 1e-4 a) |r(0)|``, halving ``a`` at most ``_MAX_HALVINGS`` times; returns
    the accepted point, or None (the caller then tries the fallback direction or cuts the load
    step, which is cheaper than creeping along a poor direction). ``link_rotation``: the step's
    coordinates are ready (:meth:`_Problem.steps`) with this largest link rotation.
    """
    state = point.state
    if link_rotation is None:
        _, link_rotation = problem.coordinates_of(state, step)
    alpha = problem.first_alpha(link_rotation)
    if problem.load_step_limit is not None:
        alpha = min(alpha, float(problem.load_step_limit(state, problem.poses(state, 1.0))))
    for _ in range(_MAX_HALVINGS):
        trial = problem.trial(state, alpha, lam)
        if trial.converged or trial.norm <= (1.0 - _ARMIJO * alpha) * point.norm:
            return trial
        alpha *= 0.5
    return None


def _newton(problem, state, lam, max_iterations):
    """Newton iterations at a fixed load factor; returns (ok, last point, iterations, why)."""
    point = problem.point(state, lam)
    iterations = 0
    while True:
        if point.converged:
            return True, point, iterations, 'converged'
        if not np.isfinite(point.measure):
            return False, point, iterations, 'non-finite residual'
        exhausted = iterations >= max_iterations
        if exhausted and not point.roundoff:
            return False, point, iterations, 'iteration budget exhausted'
        accepted, why = None, 'no tangent factors (exact singular, material not positive definite)'
        for step, method, link_rotation in problem.steps(point, lam):
            if step is None:
                why = method
                continue
            if not np.isfinite(step).all():
                why = f'non-finite Newton step ({method})'
                continue
            if point.roundoff and problem.roundoff_step(step, _ROUNDOFF_NOISE):
                # the correction is noise itself (e.g. the rest shape under no load)
                return True, point, iterations, 'converged (round-off limited)'
            if point.roundoff and problem.roundoff_step(step, _ROUNDOFF_STEP):
                problem.coordinates_of(point.state, step)
                corrected = problem.trial(point.state, 1.0, lam)
                if corrected.converged or corrected.roundoff:
                    return True, corrected, iterations + 1, 'converged (round-off limited)'
            if exhausted:
                return False, point, iterations, 'iteration budget exhausted'
            accepted = _line_search(problem, point, lam, step, link_rotation)
            if accepted is not None:
                break
            why = 'line search failed'
        iterations += 1
        if accepted is None:
            return False, point, iterations, why
        point = accepted


def solve_static(model, tip_wrench=None, frame_wrenches=None, gravity=None, *,
                 actuators=None, actuation=None, effectors=None, load_function=None,
                 load_tangent=None, load_step_limit=None, initial_state=None, tolerance=1e-10,
                 absolute_tolerance=None, max_iterations=50, max_load_steps=64,
                 max_rotation_step=None, strict=False, check_warnings=True):
    """
    Solve for the static equilibrium of a chain under loads and actuation (paper eq. 9).

    Parameters
    ----------
    model : ChainModel
        The chain; frame 0 is fixed.
    tip_wrench : (6,) array_like, optional  [N, N*m]
        Dead wrench at the last frame, world axes.
    frame_wrenches : (n, 6) array_like, optional  [N, N*m]
        Dead wrenches at frames 1..n, world axes.
    gravity : (3,) array_like, optional  [m/s^2]
        Acting on the masses lumped at frames 1..n (force only).
    actuators : cbha_inverse.core.actuation.actuators.ActuatorSet, optional
        The actuators (cables, cavities): follower loads ``J_a(q)ᵀ λ`` with their exact load
        stiffness.
    actuation : (m,) array_like, optional  [N or Pa]
        ``λ`` in actuator order (zero by default).
    effectors : cbha_inverse.core.actuation.effectors.PointEffectors, optional
        Effector points reported in the result.
    load_function : callable, optional
        ``load_function(state) -> (n, 6)`` extra configuration-dependent wrenches (world axes,
        at frames 1..n); scaled by the load factor like the dead loads.
    load_tangent : callable, optional
        ``load_tangent(state) -> (6n, 6n)`` ndarray (or None): the load stiffness
        ``-d load_function / dq`` over frames 1..n (world-axis increments as in ``retract``,
        at the full load). Without it the extra loads are not differentiated, which converges
        slowly and stalls under large follower loads.
    load_step_limit : callable, optional
        ``load_step_limit(state, stepped) -> float`` in (0, 1]: the largest fraction of the
        Newton step from ``state`` (to ``stepped``, the full step) that the line search tries
        first, for loads whose tangent changes along a step (a penalty contact that begins:
        :meth:`cbha_inverse.core.contact.PenaltyContact.step_limit`).
    initial_state : ChainState, optional
        Warm start (e.g. the previous solution): Newton on the full load from it; if that
        fails, load stepping from the rest shape (the default start). A state whose frame 0 is
        not at the model's base (a solution of the same chain on another base, e.g. another
        calibrated base offset) is first moved rigidly onto it: frame 0 is never solved for.
    tolerance : float
        Relative residual tolerance (module docstring).
    absolute_tolerance : float, optional  [N, N*m]
        Converge on ``|r|_2 <= absolute_tolerance`` instead.
    max_iterations : int
        Newton iterations allowed per load step (and for the warm start).
    max_load_steps : int
        Load steps allowed (attempts, successful or not; the warm start counts as one).
    max_rotation_step : float, optional  [rad]
        Largest link rotation of a line search's first trial step.
    strict : bool
        Raise :class:`StaticConvergenceError` instead of returning an unconverged result.
    check_warnings : bool
        Check the converged state for the warnings of the module docstring (one more
        evaluation and factorization; a plant updated at every tick turns it off).

    Returns
    -------
    StaticResult
        ``converged`` is False (with a message) if the full load was not reached.

    Raises
    ------
    ValueError
        If a load, the gravity or the actuation has the wrong shape or is not finite, or
        ``initial_state`` does not match the model.
    StaticConvergenceError
        With ``strict``, if the solve did not converge.

    """
    external = external_wrenches(model, tip_wrench, frame_wrenches, gravity)
    m = 0 if actuators is None else actuators.n_actuators
    amount = np.zeros(m) if actuation is None else checked_array(
        np.asarray(actuation, dtype=float).reshape(-1), (m,), 'actuation')
    problem = _Problem(model, actuators, amount, external, load_function, load_tangent,
                       tolerance, absolute_tolerance, max_rotation_step, load_step_limit)
    lam, increment, steps, total, message = 0.0, 1.0, 0, 0, ''
    state, warm, final = None, None, None
    if initial_state is not None:
        checked_array(initial_state.positions, (model.n_frames, 3), 'initial_state.positions')
        checked_array(initial_state.rotations, (model.n_frames, 3, 3), 'initial_state.rotations')
        initial_state = _on_base(initial_state, model)
        steps = 1
        ok, point, total, why = _newton(problem, initial_state, 1.0, max_iterations)
        if ok:
            state, lam, final = point.state, 1.0, point
        else:
            message, warm = f'warm start failed: {why}', point.state
    if state is None:
        state = problem.rest
    while lam < 1.0:
        if steps >= max_load_steps:
            message = (f'not converged: load step budget ({max_load_steps}) exhausted at load '
                       f'factor {lam:.6g} ({message})')
            break
        if increment < _MIN_LOAD_INCREMENT:
            message = (f'not converged: load increment below {_MIN_LOAD_INCREMENT:.3g} at load '
                       f'factor {lam:.6g} ({message})')
            break
        target = min(1.0, lam + increment)
        steps += 1
        ok, point, its, why = _newton(problem, state, target, max_iterations)
        total += its
        if ok:
            state, lam, final = point.state, target, point
            increment = min(2.0 * increment, 1.0)
        else:
            increment *= 0.5
            message = f'last failure at load factor {target:.6g}: {why}'
    converged = lam >= 1.0
    if converged:
        message = f'converged in {total} Newton iterations, {steps} load step(s)'
    else:
        if lam == 0.0 and warm is not None:
            state = warm  # no equilibrium reached: the warm iterate is the better place to resume
        final = problem.point(state, 1.0)
    if state is problem.rest:
        state = ChainState(state.positions.copy(), state.rotations.copy())  # keep the cache
    effector_positions = (np.zeros((0, 3)) if effectors is None
                          else effectors.positions(state.positions, state.rotations))
    warnings = _result_warnings(problem, final) if converged and check_warnings else ()
    result = StaticResult(state.positions, state.quaternions, state.rotations, state,
                          bool(converged), int(total), float(final.measure), final.residual,
                          int(steps), float(lam), message, amount, effector_positions, warnings)
    if strict and not result.converged:
        raise StaticConvergenceError(result)
    return result


def _on_base(state, model):
    """
    Return ``state`` moved rigidly so that its frame 0 is the model's base pose.

    With ``D = T_base T_0⁻¹`` (``T_0``: the state's frame 0), every frame becomes ``D T_i``: the
    shape is kept, the base matches. A state already on the base is returned as is.
    """
    if (np.array_equal(state.positions[0], model.base_position)
            and np.array_equal(state.rotations[0], model.base_rotation)):
        return state
    turn = model.base_rotation @ state.rotations[0].T
    positions = (state.positions - state.positions[0]) @ turn.T + model.base_position
    return ChainState(positions, turn @ state.rotations)


def _result_warnings(problem, point):
    """
    Return the warnings about a converged point (:mod:`cbha_inverse.core.static_warnings`).

    Parameters
    ----------
    problem : _Problem
        The problem solved.
    point : _Point
        The converged point at the full load.

    Returns
    -------
    tuple of str

    """
    state = point.state
    warnings = []
    if problem.absolute is None and point.measure > problem.tolerance * point.load_scale:
        # converged round-off limited: how large is the residual against the applied load?
        warnings.extend(roundoff_warnings(point.measure, point.residual, problem.applied(state),
                                          problem.length))
    coordinates, _ = problem.coordinates_of(state)
    warnings.extend(strain_warnings(problem.model, coordinates[:, :3], coordinates[:, 3:6]))
    load = None if problem.load_tangent is None else problem.load_tangent(state)
    warnings.extend(stability_warnings(problem.system, state, problem.actuation, load))
    return tuple(warnings)
