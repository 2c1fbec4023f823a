"""
The per-tick inverse-simulation controller (DESIGN §6, paper §IV) and closed-loop correction.

:class:`InverseSolver` holds the immutable model (chain, actuators, effectors, gravity) and a
mutable tick state (frame poses, current actuation, QP warm start). One :meth:`InverseSolver.step`:

1. linearise at the current state: tangent stiffness ``K`` and internal wrenches (the fused
   :class:`cbha_inverse.core.kernel.ChainKernel`, equal to ``assemble_tangent``), actuator
   columns ``J_aᵀ`` at the current poses, residual ``r = f(q) + f_ext + J_aᵀ λ_prev``;
2. factor ``K`` (LAPACK Cholesky of the dense block-tridiagonal matrix, the fastest exact method
   at control-scene sizes) and solve ``K⁻¹ [J_aᵀ, r]`` in one multi-RHS call, giving
   ``W_ea``, ``W_aa`` and ``δ_e^free`` (:func:`cbha_inverse.core.inverse.project_constraints`);
3. solve the regularised box QP (proxsuite, warm-started; projected Gauss-Seidel on request or as a
   fallback if proxsuite reports a failure);
4. apply ``λ`` and update the state by the Newton step of the same factorization,
   ``dq = K⁻¹ r + K⁻¹ J_aᵀ (λ - λ_prev)`` (no second solve), followed by ``newton_steps - 1``
   further full Newton steps at fixed ``λ`` if requested (or, with ``relinearize_every > 1``,
   keep the linear model for a few ticks; see :class:`InverseOptions`).

Repeated ticks therefore run Newton's method on the coupled problem (equilibrium plus optimal
actuation); at a fixed target the state converges to the static equilibrium of the returned
actuation. Each step is limited to ``max_rotation_step`` radians per frame so a far target cannot
throw the linearisation off.
"""

from dataclasses import dataclass, field
import time

from cbha_inverse.core.chain import ChainState, rest_state
from cbha_inverse.core.inverse import project_constraints, qp_matrices, qp_problem
from cbha_inverse.core.kernel import ChainKernel, DenseCholesky, DenseLU, fast_retract
from cbha_inverse.core.qp import ActuationQP, binding_bounds, projected_gauss_seidel
import numpy as np


@dataclass(frozen=True)
class InverseOptions:
    """
    Options of the inverse solver.

    Attributes
    ----------
    energy_weight : float
        ``ε_E`` of the actuation-energy term (unit-free, see :mod:`cbha_inverse.core.inverse`).
    proximal_weight : float
        ``ε_P`` of the tick-to-tick smoothing term (unit-free).
    rate_limit : tuple of float or None
        Largest change per tick of each actuator (N or Pa), ``None`` for none.
    qp_solver : str
        ``'proxsuite'`` (default) or ``'gauss_seidel'``.
    newton_steps : int
        Newton steps per tick (1 = the update reuses the tick's factorization).
    max_rotation_step : float  [rad]
        Largest frame rotation increment per Newton step.
    eps_abs : float
        QP tolerance (normalised problem).
    relinearize_every : int
        Ticks between linearisations. 1 (default) is DESIGN §6 / the paper: tangent, factor,
        ``W`` and a Newton update at every tick. ``N > 1``: a linearisation is kept for up to
        ``N`` ticks and the ticks in between solve the QP of the same linear model (paper
        eq. 11, only ``δ_free`` changes with the target; proxsuite re-solves with the same
        Hessian) and report its predicted effector positions; the next linearisation applies
        the latest actuation to the linearisation state (one Newton step), so the fixed point
        is the same static equilibrium. A linearisation is dropped early when an actuator moves
        by more than 2 % of its range in one tick (large motions relinearise every tick).

    """

    energy_weight: float = 1e-6
    proximal_weight: float = 1e-4
    rate_limit: tuple = None
    qp_solver: str = 'proxsuite'
    newton_steps: int = 1
    max_rotation_step: float = 0.5
    eps_abs: float = 1e-10
    relinearize_every: int = 1

    def __post_init__(self):
        """Validate."""
        if self.qp_solver not in ('proxsuite', 'gauss_seidel'):
            raise ValueError(f"qp_solver must be 'proxsuite' or 'gauss_seidel', "
                             f'not {self.qp_solver!r}')
        if self.newton_steps < 1:
            raise ValueError('newton_steps must be >= 1')
        if self.relinearize_every < 1:
            raise ValueError('relinearize_every must be >= 1')


@dataclass(frozen=True)
class _Linearization:
    """What a linearisation tick keeps for the linear ticks that follow it (paper eq. 11)."""

    w_ea: np.ndarray
    matrices: object
    offset: np.ndarray            # p_e + J_e K⁻¹ r - W_ea λ_prev (so δ_free = offset - target)
    free_step: np.ndarray         # K⁻¹ r
    solved_actuators: np.ndarray  # K⁻¹ J_aᵀ
    previous: np.ndarray          # λ_prev at the linearisation
    residual_norm: float


@dataclass(frozen=True)
class TickResult:
    """
    Result of one control tick.

    Attributes
    ----------
    actuation : (m,) ndarray  [N or Pa]
        Commanded actuation, always finite and within the bounds.
    effector_positions : (k, 3) ndarray  [m]
        Effector positions of the updated model state (between linearisations, with
        ``relinearize_every > 1``: the linear model's prediction).
    status : str
        ``'solved'`` (QP solved, no bound limits the tracking), ``'saturated'`` (QP solved, some
        actuator is held by a bound the target pushes against: closest reachable point),
        ``'qp_fallback'`` (proxsuite failed, the Gauss-Seidel solution is used),
        ``'not_positive_definite'`` (tangent not SPD: actuation held, state unchanged) or
        ``'rejected'`` (non-finite target: actuation held, state unchanged).
    qp_status : str
        The QP solver's own status.
    qp_iterations : int
        QP iterations.
    saturated : (m,) ndarray of bool
        Actuators held by a bound.
    predicted_error : float  [m]
        ``‖W_ea λ + δ_e^free‖`` of the linearised model (largest effector gap).
    residual_norm : float  [N, N*m]
        Norm of the equilibrium residual at the last linearisation (before its update).
    timings : dict
        Seconds spent in ``assembly``, ``factor``, ``projection``, ``qp``, ``update``, ``total``.

    """

    actuation: np.ndarray
    effector_positions: np.ndarray
    status: str
    qp_status: str
    qp_iterations: int
    saturated: np.ndarray
    predicted_error: float
    residual_norm: float
    timings: dict = field(default_factory=dict)


class InverseSolver:
    """
    The per-tick controller of DESIGN §6 (pure numerics, no ROS).

    Parameters
    ----------
    model : cbha_inverse.core.chain.ChainModel
        The frame chain.
    actuators : cbha_inverse.core.actuation.ActuatorSet
        Its actuators (``m``).
    effectors : cbha_inverse.core.effectors.PointEffectors
        Its effector points (``k``).
    gravity : (3,) array_like or None  [m/s^2]
        Gravity acting on the lumped masses.
    options : InverseOptions, optional
        Solver options.
    scale : (m,) array_like, optional
        Actuator scales ``σ`` (default: ``upper - lower``).

    """

    def __init__(self, model, actuators, effectors, gravity=None, options=None, scale=None):
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
        self._scale = (self.upper_bounds - self.lower_bounds if scale is None
                       else np.asarray(scale, dtype=float))
        self._rate = (None if self.options.rate_limit is None
                      else np.broadcast_to(np.asarray(self.options.rate_limit, float), (m,)))
        n = model.n_links
        external = np.zeros((n, 6))
        if gravity is not None:
            external[:, :3] = np.asarray(model.masses, dtype=float)[:, None] * np.asarray(gravity)
        self._external = external.reshape(-1)
        self._qp = ActuationQP(m, eps_abs=self.options.eps_abs)
        self._kernel = ChainKernel(model)
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
        self._positions = np.array(state.positions, dtype=float)
        self._rotations = np.array(state.rotations, dtype=float)
        a = np.zeros(len(self.actuator_names)) if actuation is None else actuation
        self.actuation = np.clip(np.asarray(a, dtype=float), self.lower_bounds, self.upper_bounds)
        self._qp.reset()
        self._linearization = None
        self._pending = None
        self._age = 0

    def _current(self):
        """Return the frames with the pending linear step applied (without storing them)."""
        if self._pending is None:
            return self._positions, self._rotations
        free_step, solved_a, previous = self._pending
        increments = (free_step + solved_a @ (self.actuation - previous)).reshape(-1, 6)
        return fast_retract(self._positions, self._rotations, self._limited(increments))

    def _materialise(self):
        """Apply the pending linear step to the stored frames."""
        if self._pending is not None:
            self._positions, self._rotations = self._current()
            self._pending = None

    @property
    def state(self):
        """Return a copy of the current model frames as a ``ChainState``."""
        positions, rotations = self._current()
        return ChainState(positions.copy(), rotations.copy())

    def effector_positions(self):
        """Return the effector positions (k, 3) of the current model state."""
        return self.effectors.positions(*self._current())

    def _limited(self, increments):
        """Scale a Newton step so that no frame rotates more than ``max_rotation_step``."""
        largest = np.sqrt(np.max(np.einsum('ij,ij->i', increments[:, 3:], increments[:, 3:])))
        if largest > self.options.max_rotation_step:
            increments = increments * (self.options.max_rotation_step / largest)
        return increments

    def _factor(self, tangent, positions, rotations, actuation):
        """
        Factor the tick's tangent, falling back when it is not positive definite.

        1. Cholesky of structure + symmetric load stiffness (the normal case);
        2. LU of structure + exact (non-symmetric) load stiffness (high pressures);
        3. Cholesky of the material tangent alone (paper eq. 8; far from equilibrium).
        The residual is exact in every case, so only the convergence rate changes.
        """
        try:
            return DenseCholesky(tangent)
        except np.linalg.LinAlgError:
            pass
        _, full = self._kernel.linearise(positions, rotations)
        load = self.actuators.load_tangent(positions, rotations, actuation, symmetric=False)
        if load is not None:
            try:
                return DenseLU(full + load)
            except np.linalg.LinAlgError:
                pass
        _, material = self._kernel.linearise(positions, rotations, geometric=False)
        try:
            return DenseCholesky(material)
        except np.linalg.LinAlgError:
            return None

    def _residual(self, positions, rotations, internal, actuation):
        """Return ``f(q) + f_ext + J_aᵀ λ`` (6n,) at a state."""
        wrenches, _ = self.actuators.evaluate(positions, rotations, False)
        return (internal.reshape(-1) + self._external
                + actuation @ wrenches[:, 1:, :].reshape(wrenches.shape[0], -1))

    def _held(self, status, started, qp_status='not_run'):
        """Return a tick result that keeps the actuation and the state."""
        m = self.actuation.size
        elapsed = time.perf_counter() - started
        timings = {'assembly': 0.0, 'factor': 0.0, 'projection': 0.0, 'qp': 0.0, 'update': 0.0,
                   'total': elapsed}
        return TickResult(self.actuation.copy(), self.effector_positions(), status, qp_status, 0,
                          np.zeros(m, dtype=bool), float('nan'), float('nan'), timings)

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
            If ``targets`` does not have the shape (k, 3).

        """
        t_start = time.perf_counter()
        targets = np.asarray(targets, dtype=float)
        k = self.effectors.n_effectors
        if targets.shape != (k, 3):
            if targets.size == 3 * k:
                targets = targets.reshape(k, 3)
            else:
                raise ValueError(f'targets must have shape ({k}, 3), got {targets.shape}')
        if not np.isfinite(targets).all():
            return self._held('rejected', t_start)
        lin = self._linearization
        fresh = lin is None or self._age >= self.options.relinearize_every
        if fresh:
            self._materialise()
            previous = self.actuation
            positions, rotations = self._positions, self._rotations
            internal, tangent = self._kernel.linearise(positions, rotations)
            wrenches, _ = self.actuators.evaluate(positions, rotations, False)
            m = wrenches.shape[0]
            jat = wrenches[:, 1:, :].reshape(m, -1)
            residual = internal.reshape(-1) + self._external + previous @ jat
            load_tangent = self.actuators.load_tangent(positions, rotations, previous)
            if load_tangent is not None:
                tangent = tangent + load_tangent
            t_assembly = time.perf_counter()
            factorization = self._factor(tangent, positions, rotations, previous)
            if factorization is None:
                self._linearization = None
                return self._held('not_positive_definite', t_start)
            t_factor = time.perf_counter()
            levers = self.effectors.levers(rotations)
            projection = project_constraints(factorization, jat, residual, self.effectors,
                                             levers, positions[self.effectors.frames] + levers,
                                             targets, previous)
            matrices = qp_matrices(projection.w_ea, projection.w_aa, self._scale,
                                   energy_weight=self.options.energy_weight,
                                   proximal_weight=self.options.proximal_weight)
            delta_free = projection.delta_free
            lin = _Linearization(projection.w_ea, matrices, delta_free + targets.reshape(-1),
                                 projection.solved[:, m], projection.solved[:, :m], previous,
                                 float(np.linalg.norm(residual)))
            self._linearization, self._age = lin, 1
        else:
            previous = self.actuation
            t_assembly = t_factor = t_start
            delta_free = lin.offset - targets.reshape(-1)
            self._age += 1
        t_projection = time.perf_counter()
        problem = qp_problem(lin.matrices, delta_free, previous, self.lower_bounds,
                             self.upper_bounds, rate_limit=self._rate)
        status = 'solved'
        if self.options.qp_solver == 'proxsuite':
            solution = self._qp.solve(problem, same_hessian=not fresh)
            if not solution.ok:
                status = 'qp_fallback'
                solution = projected_gauss_seidel(problem)
                solution = type(solution)(solution.x, self._qp_status_text(solution), 0, True)
        else:
            solution = projected_gauss_seidel(problem)
        actuation = np.minimum(np.maximum(problem.scale * solution.x, self.lower_bounds),
                               self.upper_bounds)
        saturated = binding_bounds(problem, solution.x)
        if status == 'solved' and saturated.any():
            status = 'saturated'
        gap = lin.w_ea @ actuation + delta_free
        if np.abs(solution.x - problem.previous).max() > 0.02:
            # the actuation moves fast: the next tick relinearises
            self._age = self.options.relinearize_every
        t_qp = time.perf_counter()
        self.actuation = actuation
        self._pending = (lin.free_step, lin.solved_actuators, lin.previous)
        if self.options.relinearize_every == 1:
            self._materialise()
            positions, rotations = self._positions, self._rotations
            for _ in range(self.options.newton_steps - 1):
                internal, tangent = self._kernel.linearise(positions, rotations)
                load_tangent = self.actuators.load_tangent(positions, rotations, actuation)
                if load_tangent is not None:
                    tangent = tangent + load_tangent
                try:
                    step = DenseCholesky(tangent).solve(
                        self._residual(positions, rotations, internal, actuation))
                except np.linalg.LinAlgError:
                    break
                positions, rotations = fast_retract(positions, rotations,
                                                    self._limited(step.reshape(-1, 6)))
            self._positions, self._rotations = positions, rotations
            effector_positions = self.effectors.positions(positions, rotations)
        else:
            # between linearisations the tick is the linear model of paper eq. 11
            effector_positions = targets + gap.reshape(-1, 3)
        t_end = time.perf_counter()
        timings = {'assembly': t_assembly - t_start, 'factor': t_factor - t_assembly,
                   'projection': t_projection - t_factor, 'qp': t_qp - t_projection,
                   'update': t_end - t_qp, 'total': t_end - t_start}
        return TickResult(actuation, effector_positions, status, solution.status,
                          solution.iterations, saturated,
                          float(np.sqrt((gap.reshape(-1, 3) ** 2).sum(axis=1).max())),
                          lin.residual_norm, timings)

    @staticmethod
    def _qp_status_text(solution):
        """Label the Gauss-Seidel fallback's status."""
        return f'gauss_seidel_{solution.status}'


class TargetCorrector:
    """
    Closed-loop target correction: integral action on the measured effector error (DESIGN §6).

    The model is asked to reach ``target + c``; every update integrates
    ``c ← c + gain · (target - measured)`` and clamps ``|c|`` per effector to ``max_correction``.
    Anti-windup: while the solver reports saturation, an update that would increase ``|c|`` is
    skipped (conditional integration). Effectors without a measurement (NaN rows) are not
    integrated. Open loop is ``gain = 0`` (the paper's mode).

    Parameters
    ----------
    n_effectors : int
        ``k``.
    gain : float
        Integral gain per update (dimensionless, 0..1; e.g. 0.1 at 50 Hz).
    max_correction : float  [m]
        Largest correction per effector.

    """

    def __init__(self, n_effectors, gain=0.1, max_correction=0.03):
        """Start with no correction."""
        if not 0.0 <= gain <= 1.0:
            raise ValueError('gain must lie in [0, 1]')
        self.gain = float(gain)
        self.max_correction = float(max_correction)
        self.correction = np.zeros((int(n_effectors), 3))

    def reset(self):
        """Forget the integral."""
        self.correction[:] = 0.0

    def update(self, target, measured, saturated=False):
        """
        Integrate one measurement and return the corrected target.

        Parameters
        ----------
        target : (k, 3) array_like  [m]
            Desired effector positions.
        measured : (k, 3) array_like or None  [m]
            Measured positions (NaN rows: not measured; None: nothing measured).
        saturated : bool
            Whether the last tick saturated (anti-windup).

        Returns
        -------
        (k, 3) ndarray  [m]
            ``target + c``.

        """
        target = np.asarray(target, dtype=float).reshape(self.correction.shape)
        if measured is not None and self.gain > 0.0:
            error = target - np.asarray(measured, dtype=float).reshape(target.shape)
            valid = np.all(np.isfinite(error), axis=1)
            proposal = self.correction + self.gain * np.where(valid[:, None], error, 0.0)
            norms = np.linalg.norm(proposal, axis=1)
            too_long = norms > self.max_correction
            proposal[too_long] *= (self.max_correction / norms[too_long])[:, None]
            if saturated:
                grows = np.linalg.norm(proposal, axis=1) > np.linalg.norm(self.correction, axis=1)
                proposal[grows] = self.correction[grows]
            self.correction = proposal
        return target + self.correction
