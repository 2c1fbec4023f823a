"""
Quasi-static equilibrium of a frame chain under loads and actuation (paper eq. 9, DESIGN §3, §11).

:func:`solve_static` is the package's one solver of eq. 9, behind the scenes' forward model
(:meth:`cbha_inverse.scene.Scene.forward`) and the simulated plant
(:class:`cbha_inverse.robot.plant.StaticPlant`). It solves, for the poses of frames 1..n,

    r(q) = f(q) + lam (f_dead + J_a(q)ᵀ λ + f_load(q)) = 0

with ``f`` the internal wrenches, ``f_dead`` constant world wrenches (tip, frame wrenches,
gravity: :func:`external_wrenches`), ``J_a(q)ᵀ λ`` the actuators' configuration-dependent
(follower) wrenches, ``f_load`` optional user follower loads and ``lam`` the load factor. The
residual and every tangent come from the compiled kernels the control tick runs
(:class:`cbha_inverse.core.system.EquilibriumSystem`), so the controller, the statics and the plant
evaluate the same physics with the same code:

- Newton increments ``dq = T⁻¹ r`` (world axes, as for :func:`cbha_inverse.core.chain.retract`)
  with ``T = -dr/dq`` the exact, non-symmetric tangent: material + geometric part of the links
  and the actuators' exact load stiffness (quadratic convergence; the structural tangent alone
  sees a tendon-compressed backbone as unstable), factored by LAPACK's band LU (``dgbtrf``,
  the bandwidth of the scene, O(n)). If the tangent is singular, the step is not finite or the
  line search rejects it, the iteration falls back to the material tangent (paper eq. 8, SPD
  whatever the stresses, compiled band Cholesky): a modified-Newton step, robust where ``T``
  is indefinite or singular (a chain near a limit point, high pressure);
- the increment is applied in the chain's deformation coordinates
  (:func:`cbha_inverse.core._kernels.retraction.deformation_step`): full Newton steps stay
  acceptable at large rotations of slender chains (the PL^2/EI = 10 elastica converges from rest
  in one load step of 7 iterations);
- backtracking line search on the Euclidean norm of the scaled residual (Armijo, factor 1/2),
  optionally starting from a step shortened so that no link turns by more than
  ``max_rotation_step``;
- load stepping: a warm start (``initial_state``) is tried at the full load first; otherwise or
  if it fails, the full load from the rest shape; a load step that fails (no convergence within
  ``max_iterations`` or a failed line search) is halved, successful steps double the increment.

Convergence test (``residual_norm`` reports the left-hand side), by default relative::

    max |r_scaled| <= tolerance * load_scale + floor

``r_scaled`` is the residual with moments divided by the chain length L_c (so both are in N);
``load_scale`` is the largest scaled component of the applied loads and of the internal wrenches
at the current state; ``floor`` is the round-off level of the internal forces,
``64 eps max_links(|K_tt| x_ref + |K_tr|, (|K_rt| x_ref + |K_rr|) / L_c)`` with ``x_ref = L_c +
|base position|`` (max-abs entries of the stiffness blocks), below which no residual is
meaningful. With ``absolute_tolerance`` the test is instead ``|r|_2 <= absolute_tolerance``
(unscaled Euclidean norm in N and N*m, the plant's contract).
"""

from dataclasses import dataclass
from typing import NamedTuple
import weakref

from cbha_inverse.core._kernels.residual import residual_measures
from cbha_inverse.core._kernels.retraction import deformation_step, deformed_poses
from cbha_inverse.core.actuation.actuators import ActuatorSet
from cbha_inverse.core.chain import ChainState, checked_array, rest_state
from cbha_inverse.core.system import EquilibriumSystem
import numpy as np

_ARMIJO = 1e-4
_MAX_HALVINGS = 6
_MIN_LOAD_INCREMENT = 1.0 / 2 ** 20


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


def external_wrenches(model, tip_wrench=None, frame_wrenches=None, gravity=None):
    """
    Dead external wrenches on frames 1..n (world axes, at the frame origins).

    The one place where gravity becomes frame wrenches (the controller, the statics, the
    scenes and the plant all call it).

    Parameters
    ----------
    model : ChainModel
        The chain (masses are lumped at frames 1..n).
    tip_wrench : (6,) array_like, optional  [N, N*m]
        Added at the last frame.
    frame_wrenches : (n, 6) array_like, optional  [N, N*m]
        Wrench on each of frames 1..n.
    gravity : (3,) array_like, optional  [m/s^2]
        Acceleration of gravity; force ``m_i g`` on frame i.

    Returns
    -------
    (n, 6) ndarray

    """
    n = model.n_links
    ext = np.zeros((n, 6))
    if frame_wrenches is not None:
        ext += checked_array(frame_wrenches, (n, 6), 'frame_wrenches')
    if tip_wrench is not None:
        ext[-1] += checked_array(tip_wrench, (6,), 'tip_wrench')
    if gravity is not None:
        ext[:, :3] += model.masses[:, None] * checked_array(gravity, (3,), 'gravity')
    return ext


def chain_stiffness(model, state=None):
    """
    Return the symmetric tangent stiffness of a bare chain over frames 1..n (dense).

    Parameters
    ----------
    model : ChainModel
        The chain.
    state : ChainState, optional
        Frame poses (default: the rest shape, where the tangent is the assembled ``K`` of the
        links, paper eq. 8).

    Returns
    -------
    (6n, 6n) ndarray  [N/m, N, N*m/rad]

    """
    state = rest_state(model) if state is None else state
    system = _system(model, None)
    tangent, _ = system.linearise(state.positions, state.rotations, np.zeros(0))
    lower = system.dense(tangent)
    return lower + np.tril(lower, -1).T


def _residual_floor(model, length):
    """Round-off level of the scaled internal wrenches (see the module docstring)."""
    k = np.abs(model.stiffnesses)
    k_tt = k[:, :3, :3].max()
    k_tr = max(k[:, :3, 3:].max(), k[:, 3:, :3].max())
    k_rr = k[:, 3:, 3:].max()
    x_ref = length + float(np.linalg.norm(model.base_position))
    return 64.0 * np.finfo(float).eps * max(k_tt * x_ref + k_tr, (k_tr * x_ref + k_rr) / length)


_SYSTEMS = weakref.WeakKeyDictionary()


def _system(model, actuators):
    """
    Return the compiled evaluator of a chain and its actuators, built once per pair.

    Its constant external wrenches are zero: the static problem adds its own dead loads.
    """
    per_model = _SYSTEMS.setdefault(model, {'chain': None,
                                            'actuated': weakref.WeakKeyDictionary()})
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
    norm: float            # Euclidean norm of the scaled residual (line search)
    converged: bool


class _Problem:
    """One static problem: compiled evaluator, loads, convergence test and tangent solves."""

    def __init__(self, model, actuators, actuation, external, load_function, load_tangent,
                 tolerance, absolute_tolerance, max_rotation_step):
        self.model = model
        self.system = _system(model, actuators)
        self.actuation = actuation
        self.external = np.ascontiguousarray(external, dtype=float).reshape(-1)
        self._no_extra = np.zeros(6 * model.n_links)
        self.load_function = load_function
        self.load_tangent = load_tangent
        self.tolerance = float(tolerance)
        self.absolute = None if absolute_tolerance is None else float(absolute_tolerance)
        self.max_rotation_step = max_rotation_step
        self.length = model.length if model.length > 0.0 else 1.0
        self.floor = _residual_floor(model, self.length)
        self.rest_rotations = np.ascontiguousarray(model.rest_rotations, dtype=float)
        self.coordinates = np.empty((model.n_links, 12))
        self._evaluated = None

    def point(self, state, lam):
        """Evaluate a state at load factor ``lam`` (residual, convergence test)."""
        n = self.model.n_links
        actuation = lam * self.actuation
        rhs = self.system.evaluate(state.positions, state.rotations, actuation)
        self._evaluated = (state, lam)
        extra = self._no_extra
        if self.load_function is not None:
            extra = np.asarray(self.load_function(state), dtype=float)
            if extra.shape != (n, 6):
                raise ValueError(f'load_function must return shape {(n, 6)}')
            extra = np.ascontiguousarray(extra.reshape(-1))
        res = np.empty(6 * n)
        measure, r_two, norm, scale = residual_measures(rhs, actuation, self.external, extra,
                                                        lam, self.length, res)
        res = res.reshape(n, 6)
        if self.absolute is not None:
            return _Point(state, res, norm, r_two, norm <= self.absolute)
        return _Point(state, res, measure, r_two, measure <= self.tolerance * scale + self.floor)

    def exact_step(self, state, lam, res):
        """Newton step with the exact tangent (band LU)."""
        if self._evaluated != (state, lam):
            self.point(state, lam)
        tangent = self.system.exact_tangent()
        load = None if self.load_tangent is None or lam == 0.0 else self.load_tangent(state)
        if load is not None:
            matrix = self.system.dense_exact(tangent) + lam * np.asarray(load, dtype=float)
            step = np.linalg.solve(matrix, res.reshape(-1))
        else:
            factor = self.system.factor_exact(tangent)
            if factor is None:
                raise np.linalg.LinAlgError('singular tangent')
            step = factor.solve(res.reshape(-1))
        if not np.all(np.isfinite(step)):
            raise np.linalg.LinAlgError('singular tangent (non-finite Newton step)')
        return step.reshape(-1, 6)

    def material_step(self, state, lam, res):
        """Modified-Newton step with the material tangent (SPD, band Cholesky): the fallback."""
        tangent, _ = self.system.material_system(state.positions, state.rotations,
                                                 lam * self.actuation)
        self._evaluated = None
        factor = self.system.factor(tangent)
        if factor is None:
            raise np.linalg.LinAlgError('material tangent not positive definite')
        step = self.system.solve(factor, res.reshape(-1, 1))
        if not np.all(np.isfinite(step)):
            raise np.linalg.LinAlgError('non-finite material step')
        return step.reshape(-1, 6)

    def first_alpha(self, link_rotation):
        """Return the first line-search step: no link turns by more than the limit."""
        limit = self.max_rotation_step
        if limit is None or link_rotation <= limit:
            return 1.0
        return limit / link_rotation

    def poses(self, state, alpha):
        """Return the state of the last :func:`deformation_step` advanced by ``alpha``."""
        positions, rotations = state.positions.copy(), state.rotations.copy()
        deformed_poses(self.coordinates, alpha, self.rest_rotations, positions, rotations)
        return ChainState(positions, rotations)


def _line_search(problem, point, lam, step):
    """
    Backtrack along the Newton step (in deformation coordinates) on the residual norm.

    Armijo test on the Euclidean norm of the scaled residual, ``|r(a)| <= (1 - 1e-4 a) |r(0)|``,
    halving ``a`` at most ``_MAX_HALVINGS`` times; returns the accepted point, or None (the
    caller then tries the fallback direction or cuts the load step, which is cheaper than
    creeping along a poor direction).
    """
    state = point.state
    link_rotation = deformation_step(
        np.ascontiguousarray(state.positions, dtype=float),
        np.ascontiguousarray(state.rotations, dtype=float), problem.rest_rotations,
        np.ascontiguousarray(step, dtype=float), problem.coordinates)
    alpha = problem.first_alpha(link_rotation)
    for _ in range(_MAX_HALVINGS):
        trial = problem.point(problem.poses(state, alpha), lam)
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
        if iterations >= max_iterations:
            return False, point, iterations, 'iteration budget exhausted'
        iterations += 1
        accepted, why = None, ''
        for direction in (problem.exact_step, problem.material_step):
            try:
                step = direction(point.state, lam, point.residual)
            except np.linalg.LinAlgError as exc:
                why = str(exc) or 'singular tangent'
                continue
            accepted = _line_search(problem, point, lam, step)
            if accepted is not None:
                break
            why = 'line search failed'
        if accepted is None:
            return False, point, iterations, why
        point = accepted


def solve_static(model, tip_wrench=None, frame_wrenches=None, gravity=None, *,
                 actuators=None, actuation=None, effectors=None, load_function=None,
                 load_tangent=None, initial_state=None, tolerance=1e-10,
                 absolute_tolerance=None, max_iterations=50, max_load_steps=64,
                 max_rotation_step=None, strict=False):
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
    initial_state : ChainState, optional
        Warm start (e.g. the previous solution): Newton on the full load from it; if that
        fails, load stepping from the rest shape (the default start).
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

    Returns
    -------
    StaticResult
        ``converged`` is False (with a message) if the full load was not reached.

    """
    external = external_wrenches(model, tip_wrench, frame_wrenches, gravity)
    m = 0 if actuators is None else actuators.n_actuators
    amount = np.zeros(m) if actuation is None else checked_array(
        np.asarray(actuation, dtype=float).reshape(-1), (m,), 'actuation')
    problem = _Problem(model, actuators, amount, external, load_function, load_tangent,
                       tolerance, absolute_tolerance, max_rotation_step)
    lam, increment, steps, total, message = 0.0, 1.0, 0, 0, ''
    state, warm, final = None, None, None
    if initial_state is not None:
        if initial_state.positions.shape != (model.n_frames, 3):
            raise ValueError('initial_state does not match the model')
        steps = 1
        ok, point, total, why = _newton(problem, initial_state, 1.0, max_iterations)
        if ok:
            state, lam, final = point.state, 1.0, point
        else:
            message, warm = f'warm start failed: {why}', point.state
    if state is None:
        state = rest_state(model)
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
    effector_positions = (np.zeros((0, 3)) if effectors is None
                          else effectors.positions(state.positions, state.rotations))
    result = StaticResult(state.positions, state.quaternions, state.rotations, state,
                          bool(converged), int(total), float(final.measure), final.residual,
                          int(steps), float(lam), message, amount, effector_positions)
    if strict and not result.converged:
        raise StaticConvergenceError(result)
    return result
