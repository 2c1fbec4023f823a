"""
Inverse model in constraint space (paper §IV, eq. 11-13; DESIGN §6 steps 2-3).

The mechanics linearised at the current state, ``K dq = r + J_aᵀ (λ - λ_prev)`` with the current
residual ``r = f(q) + f_ext + J_aᵀ λ_prev``, is projected onto the effectors and the actuators with
one multi-right-hand-side solve ``X = K⁻¹ [J_aᵀ, r]``:

    δ_e = W_ea λ + δ_e^free,   W_ea = J_e K⁻¹ J_aᵀ                         (eq. 11)
    δ_a = W_aa λ + δ_a^free,   W_aa = J_a K⁻¹ J_aᵀ                         (eq. 12)

where the free gaps are those of the linearised model with the actuation removed (``λ = 0``, the
paper's definition): ``δ_e^free = p_e - p_target + J_e K⁻¹ r - W_ea λ_prev``.

The actuation is the solution of the box-constrained QP (eq. 13 plus regularisation)

    min_λ  ½‖W_ea λ + δ_e^free‖² + ½ ε_E s_E λᵀ W_aa λ + ½ ε_P s_P ‖(λ - λ_prev)/σ‖²
    s.t.   max(lb, λ_prev - rate) ≤ λ ≤ min(ub, λ_prev + rate)

with ``σ`` the per-actuator range (so the problem is solved in dimensionless ``x = λ/σ``), ``s_E``
and ``s_P`` scale factors that give both terms the magnitude of the tracking term
(``s = trace(σ W_eaᵀ W_ea σ) / trace(σ W_aa σ)`` and ``trace(σ W_eaᵀ W_ea σ) / m``), so ``ε_E`` and
``ε_P`` are unit-free. ``λᵀ W_aa λ`` is the elastic energy the actuation stores in the structure:
it picks the least-effort solution among redundant ones (no co-contraction) and makes the QP
strictly convex; the proximal term smooths the actuation from tick to tick and vanishes at a fixed
point, so it adds no steady-state error. Defaults (see
:class:`cbha_inverse.core.control.InverseOptions`): ``ε_E = 1e-6`` (its bias on a reachable target
is a few micrometres at most), ``ε_P = 1e-4`` (enough to stop redundant tendons from alternating
between equivalent solutions on a saturated target).
"""

from dataclasses import dataclass

import numpy as np
import proxsuite


@dataclass(frozen=True)
class Projection:
    """
    The mechanics projected onto the effectors and actuators (paper eq. 11-12).

    Attributes
    ----------
    w_ea : (3k, m) ndarray
        Effector-actuator compliance ``J_e K⁻¹ J_aᵀ``  [m per N or Pa].
    w_aa : (m, m) ndarray
        Actuator-actuator compliance ``J_a K⁻¹ J_aᵀ``.
    delta_free : (3k,) ndarray  [m]
        Effector-to-target gap of the linearised model without actuation.
    solved : (6n, m + 1) ndarray
        ``K⁻¹ [J_aᵀ, r]``, reused for the state update.

    """

    w_ea: np.ndarray
    w_aa: np.ndarray
    delta_free: np.ndarray
    solved: np.ndarray


def project_constraints(factorization, jat, residual, effectors, levers, effector_positions,
                        targets, previous):
    """
    Compute ``W_ea``, ``W_aa`` and ``δ_e^free`` with one multi-RHS solve (paper eq. 11-12).

    Parameters
    ----------
    factorization : object with ``solve(rhs)``
        Factorization of the tangent stiffness ``K`` (6n x 6n, block tridiagonal).
    jat : (m, 6n) ndarray
        ``J_aᵀ`` stored by rows (one row per actuator) over frames ``1..n``.
    residual : (6n,) ndarray  [N, N*m]
        ``f(q) + f_ext + J_aᵀ λ_prev`` at the current state.
    effectors : cbha_inverse.core.effectors.PointEffectors
        The effector points.
    levers : (k, 3) ndarray  [m]
        Effector levers at the current state.
    effector_positions : (k, 3) ndarray  [m]
        Effector positions at the current state.
    targets : (k, 3) ndarray  [m]
        Desired positions.
    previous : (m,) ndarray
        ``λ_prev`` (the actuation contained in ``residual``).

    Returns
    -------
    Projection
        The projected problem.

    """
    m = jat.shape[0]
    rhs = np.empty((jat.shape[1], m + 1))
    rhs[:, :m] = jat.T
    rhs[:, m] = residual
    solved = factorization.solve(rhs)
    moved = effectors.apply_jacobian(solved.reshape(-1, 6, m + 1), levers)
    w_ea = moved[:, :, :m].reshape(-1, m)
    w_aa = jat @ solved[:, :m]
    delta_free = ((effector_positions - targets).reshape(-1) + moved[:, :, m].reshape(-1)
                  - w_ea @ previous)
    return Projection(w_ea, w_aa, delta_free, solved)


@dataclass(frozen=True)
class QPProblem:
    """
    The actuation QP in dimensionless variables ``x = λ / σ`` (see the module docstring).

    Attributes
    ----------
    hessian : (m, m) ndarray
    gradient : (m,) ndarray
    lower, upper : (m,) ndarray
        Box bounds of ``x`` (actuator bounds intersected with the rate limits).
    scale : (m,) ndarray
        ``σ``: ``λ = σ x``.
    previous : (m,) ndarray
        ``x_prev``.
    tracking_hessian, tracking_gradient : (m, m), (m,) ndarray
        The tracking term alone (``½‖W_ea λ + δ_e^free‖²``, normalised), for saturation checks.

    """

    hessian: np.ndarray
    gradient: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    scale: np.ndarray
    previous: np.ndarray
    tracking_hessian: np.ndarray
    tracking_gradient: np.ndarray


def actuation_qp(projection, previous, lower_bounds, upper_bounds, scale, *,
                 energy_weight=1e-6, proximal_weight=1e-4, rate_limit=None):
    """
    Build the regularised, normalised QP of paper eq. 13 (module docstring).

    Parameters
    ----------
    projection : Projection
        From :func:`project_constraints`.
    previous : (m,) ndarray
        ``λ_prev``.
    lower_bounds, upper_bounds : (m,) ndarray
        Actuator bounds.
    scale : (m,) ndarray
        ``σ`` (actuator range), positive and finite.
    energy_weight : float
        ``ε_E`` (unit-free).
    proximal_weight : float
        ``ε_P`` (unit-free).
    rate_limit : (m,) ndarray or None
        Largest change of each actuator per tick (same unit as the actuation).

    Returns
    -------
    QPProblem
        The problem, ready for :class:`ActuationQP` or :func:`projected_gauss_seidel`.

    """
    w = projection.w_ea * scale
    tracking = w.T @ w
    m = scale.size
    norm = np.trace(tracking) / m
    if not norm > 0.0:
        norm = 1.0
    energy = projection.w_aa * np.outer(scale, scale)
    energy_norm = np.trace(energy) / m
    x_prev = previous / scale
    tracking /= norm
    tracking_gradient = (w.T @ projection.delta_free) / norm
    hessian = tracking + proximal_weight * np.eye(m)
    if energy_norm > 0.0 and energy_weight > 0.0:
        hessian += (energy_weight / energy_norm) * 0.5 * (energy + energy.T)
    gradient = tracking_gradient - proximal_weight * x_prev
    lower = lower_bounds / scale
    upper = upper_bounds / scale
    if rate_limit is not None:
        lower = np.maximum(lower, x_prev - rate_limit / scale)
        upper = np.minimum(upper, x_prev + rate_limit / scale)
    return QPProblem(hessian, gradient, lower, upper, scale, x_prev, tracking, tracking_gradient)


_STATUS = {
    'PROXQP_SOLVED': 'solved',
    'PROXQP_MAX_ITER_REACHED': 'max_iterations',
    'PROXQP_PRIMAL_INFEASIBLE': 'primal_infeasible',
    'PROXQP_SOLVED_CLOSEST_PRIMAL_FEASIBLE': 'closest_primal_feasible',
    'PROXQP_DUAL_INFEASIBLE': 'dual_infeasible',
    'PROXQP_NOT_RUN': 'not_run',
}


@dataclass(frozen=True)
class QPSolution:
    """
    A QP solution in dimensionless variables.

    Attributes
    ----------
    x : (m,) ndarray
        Solution, clipped into the box (removes the solver's round-off violations).
    status : str
        ``'solved'``, ``'max_iterations'``, ``'primal_infeasible'``, ... (proxsuite's status) or
        ``'converged'`` / ``'max_iterations'`` for Gauss-Seidel.
    iterations : int
        Solver iterations.
    ok : bool
        Whether ``x`` is a solution (solved / converged).

    """

    x: np.ndarray
    status: str
    iterations: int
    ok: bool


class ActuationQP:
    """
    Reusable proxsuite dense box-QP, warm-started from the previous result.

    Parameters
    ----------
    n_actuators : int
        ``m``.
    eps_abs : float
        Absolute tolerance of the normalised problem.
    max_iterations : int
        proxsuite iteration limit.

    """

    def __init__(self, n_actuators, eps_abs=1e-10, max_iterations=1000):
        """Create the proxsuite object (initialised on the first solve)."""
        self.n_actuators = int(n_actuators)
        self.eps_abs = float(eps_abs)
        self.max_iterations = int(max_iterations)
        self.reset()

    def reset(self):
        """Forget the warm start."""
        qp = proxsuite.proxqp.dense.QP(self.n_actuators, 0, 0, True)
        qp.settings.eps_abs = self.eps_abs
        qp.settings.eps_rel = 0.0
        qp.settings.max_iter = self.max_iterations
        qp.settings.verbose = False
        self._qp = qp
        self._initialised = False

    def solve(self, problem):
        """
        Solve a :class:`QPProblem`.

        Parameters
        ----------
        problem : QPProblem
            The normalised QP.

        Returns
        -------
        QPSolution
            The solution and proxsuite's status (always checked by the caller).

        """
        qp = self._qp
        if not self._initialised:
            qp.init(problem.hessian, problem.gradient, None, None, None, None, None,
                    problem.lower, problem.upper)
            qp.solve()
            # warm start only once a previous result exists (proxsuite 0.8 crashes otherwise)
            qp.settings.initial_guess = (
                proxsuite.proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT)
            self._initialised = True
        else:
            qp.update(H=problem.hessian, g=problem.gradient, l_box=problem.lower,
                      u_box=problem.upper, update_preconditioner=False)
            qp.solve()
        info = qp.results.info
        status = _STATUS.get(info.status.name, info.status.name)
        x = qp.results.x
        ok = status == 'solved' and bool(np.all(np.isfinite(x)))
        if not ok:
            self.reset()
        x = polish(problem, np.clip(x, problem.lower, problem.upper)) if ok else np.clip(
            problem.previous, problem.lower, problem.upper)
        return QPSolution(x, status, int(info.iter), ok)


def polish(problem, x, tolerance=1e-4):
    """
    Refine an approximate box-QP solution on its active set (exact KKT point if it is one).

    proxsuite's augmented-Lagrangian iterate leaves the bound-active variables a little inside
    the box (about ``sqrt(eps)``). Fixing the variables within ``tolerance`` of a bound whose
    gradient pushes outward and solving the equality-constrained problem of the others gives the
    exact solution; it is accepted only if it is feasible, its active multipliers have the right
    sign and it does not increase the objective, otherwise ``x`` is returned unchanged.

    Parameters
    ----------
    problem : QPProblem
        The normalised QP.
    x : (m,) ndarray
        Approximate solution inside the box.
    tolerance : float
        Distance to a bound (dimensionless) below which a variable is tried as active.

    Returns
    -------
    (m,) ndarray
        The refined (or the given) solution.

    """
    h, g = problem.hessian, problem.gradient
    grad = h @ x + g
    at_lower = (x - problem.lower < tolerance) & (grad > 0.0)
    at_upper = (problem.upper - x < tolerance) & (grad < 0.0)
    active = at_lower | at_upper
    if not active.any():
        try:
            y = np.linalg.solve(h, -g)
        except np.linalg.LinAlgError:
            return x
        return y if _inside(problem, y) else x
    y = x.copy()
    y[at_lower] = problem.lower[at_lower]
    y[at_upper] = problem.upper[at_upper]
    free = ~active
    if free.any():
        try:
            y[free] = np.linalg.solve(h[np.ix_(free, free)],
                                      -g[free] - h[np.ix_(free, active)] @ y[active])
        except np.linalg.LinAlgError:
            return x
    grad = h @ y + g
    if not (_inside(problem, y) and np.all(grad[at_lower] >= 0.0)
            and np.all(grad[at_upper] <= 0.0)):
        return x
    objective = 0.5 * y @ h @ y + g @ y
    return y if objective <= 0.5 * x @ h @ x + g @ x else x


def _inside(problem, x):
    """Whether ``x`` lies in the box of ``problem``."""
    return bool(np.all(x >= problem.lower) and np.all(x <= problem.upper))


def projected_gauss_seidel(problem, x0=None, max_iterations=500, tolerance=1e-10):
    """
    Solve the box QP by projected Gauss-Seidel, as the paper's solver does (§IV).

    Each sweep sets ``x_i = clip(x_i - (H x + g)_i / H_ii, lower_i, upper_i)``.

    Parameters
    ----------
    problem : QPProblem
        The normalised QP.
    x0 : (m,) ndarray, optional
        Start (default: ``problem.previous`` clipped into the box).
    max_iterations : int
        Maximum number of sweeps.
    tolerance : float
        Stop when the largest change of a sweep is below this (dimensionless).

    Returns
    -------
    QPSolution
        ``status`` ``'converged'`` or ``'max_iterations'``.

    """
    h, g = problem.hessian, problem.gradient
    lo, up = problem.lower, problem.upper
    x = np.clip(problem.previous if x0 is None else np.asarray(x0, dtype=float), lo, up).copy()
    diag = np.diag(h).copy()
    grad = h @ x + g
    for sweep in range(1, max_iterations + 1):
        change = 0.0
        for i in range(x.size):
            new = min(max(x[i] - grad[i] / diag[i], lo[i]), up[i])
            step = new - x[i]
            if step != 0.0:
                grad += step * h[:, i]
                x[i] = new
                change = max(change, abs(step))
        if change < tolerance:
            return QPSolution(x, 'converged', sweep, True)
    return QPSolution(x, 'max_iterations', max_iterations, False)


def binding_bounds(problem, x, tolerance=1e-6):
    """
    Return which actuators are held by a bound that the tracking term pushes against (saturation).

    Only the tracking part of the objective counts: a slack cable held at zero tension by the
    energy term is not saturated, a cable that would need to push is.

    Parameters
    ----------
    problem : QPProblem
        The normalised QP.
    x : (m,) ndarray
        Its solution.
    tolerance : float
        Dimensionless tolerance on the distance to the bound and on the gradient.

    Returns
    -------
    (m,) ndarray of bool
        ``True`` where ``x`` sits on a bound and the tracking gradient points out of the box.

    """
    grad = problem.tracking_hessian @ x + problem.tracking_gradient
    at_lower = (x <= problem.lower + tolerance) & (grad > tolerance)
    at_upper = (x >= problem.upper - tolerance) & (grad < -tolerance)
    return at_lower | at_upper
