"""
The actuation QP of a tick: the inverse model in constraint space and its solvers.

The problem (paper Sec. IV, eq. 11-13): the mechanics linearised at the current state,
``K dq = r + J_aᵀ (λ - λ_prev)`` with the current residual ``r = f(q) + f_ext + J_aᵀ λ_prev``,
is projected onto the effectors and the actuators with one multi-right-hand-side solve
``X = K⁻¹ [J_aᵀ, r]``:

    δ_e = W_ea λ + δ_e^free,   W_ea = J_e K⁻¹ J_aᵀ                         (eq. 11)
    δ_a = W_aa λ + δ_a^free,   W_aa = J_a K⁻¹ J_aᵀ                         (eq. 12)

where the free gaps are those of the linearised model with the actuation removed (``λ = 0``, the
paper's definition): ``δ_e^free = p_e - p_target + J_e K⁻¹ r - W_ea λ_prev``.

The actuation is the solution of the box-constrained QP (eq. 13 plus regularisation)

    min_λ  ½‖Ω (W_ea λ + δ_e^free)‖² + ½ ε_E s_E λᵀ W_aa λ + ½ ε_P s_P ‖(λ - λ_prev)/σ‖²
    s.t.   max(lb, λ_prev - rate) ≤ λ ≤ min(ub, λ_prev + rate)

with ``Ω = diag(ω)`` the effectors' row weights (all 1 for point effectors, the paper's term;
the rotational rows of ``axis`` and ``pose`` effectors weigh one radian as
``orientation_length`` metres, :mod:`cbha_inverse.core.actuation.effectors`,
``docs/effectors.md``), ``σ`` the per-actuator range (so the problem is solved in dimensionless
``x = λ/σ``), ``s_E`` and ``s_P`` scale factors that give both terms the magnitude of the
tracking term (``s = trace(σ W_eaᵀ Ω² W_ea σ) / trace(σ W_aa σ)`` and
``trace(σ W_eaᵀ Ω² W_ea σ) / m``), so ``ε_E`` and ``ε_P`` are unit-free. ``λᵀ W_aa λ`` is the
elastic energy the actuation stores in the structure: it picks the least-effort solution among
redundant ones (no co-contraction) and makes the QP strictly convex; the proximal term smooths
the actuation from tick to tick and vanishes at a fixed point, so it adds no steady-state error.
Defaults (see :class:`cbha_inverse.core.inverse.results.InverseOptions`): ``ε_E = 1e-6`` (its
bias on a reachable target is a few micrometres at most), ``ε_P = 1e-4`` (enough to stop
redundant tendons from alternating between equivalent solutions on a saturated target).

The solvers (:data:`QP_SOLVERS`, the ``qp_solver`` option of
:class:`~cbha_inverse.core.inverse.results.InverseOptions`): :class:`ActiveSetQP` (exact,
principal pivoting on the active set), :class:`ProxsuiteQP` (proxsuite's dense QP,
warm-started; its status is always returned to the caller, and its iterate is polished onto its
active set) and :func:`projected_gauss_seidel` (the paper's solver). :func:`binding_bounds` tells
which bounds saturate the tracking. The arithmetic runs in the compiled kernels of
:mod:`cbha_inverse.core._kernels.qp`.
"""

import math
from typing import NamedTuple

from cbha_inverse.core._kernels import qp as qp_kernels
import numpy as np
import proxsuite

#: the ``qp_solver`` choices of :class:`~cbha_inverse.core.inverse.results.InverseOptions`
QP_SOLVERS = ('active_set', 'proxsuite', 'gauss_seidel')


class QPProblem(NamedTuple):
    """
    The actuation QP in dimensionless variables ``x = λ / σ`` (see the module docstring).

    Immutable (a named tuple: built every tick, five times cheaper than a frozen dataclass).

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


class QPMatrices(NamedTuple):
    """
    The parts of the actuation QP that depend only on the linearisation (not on the target).

    Attributes
    ----------
    hessian : (m, m) ndarray
        Full normalised Hessian (tracking + energy + proximal).
    tracking_hessian : (m, m) ndarray
        Normalised ``σ W_eaᵀ Ω² W_ea σ`` (``Ω``: the effectors' row weights).
    weighted_w : (r, m) ndarray
        ``Ω² W_ea σ / norm`` (the gradient is ``weighted_wᵀ δ_free - ε_P x_prev``).
    scale : (m,) ndarray
        ``σ``.
    proximal_weight : float
        ``ε_P``.

    """

    hessian: np.ndarray
    tracking_hessian: np.ndarray
    weighted_w: np.ndarray
    scale: np.ndarray
    proximal_weight: float


def qp_matrices(w_ea, w_aa, scale, *, energy_weight=1e-6, proximal_weight=1e-4,
                row_weights=None):
    """
    Return the normalised Hessian parts of the actuation QP (module docstring).

    Parameters
    ----------
    w_ea : (r, m) ndarray
        Effector-actuator compliance (``3k`` position rows, then the rotational rows).
    w_aa : (m, m) ndarray
        Actuator-actuator compliance.
    scale : (m,) ndarray
        ``σ``.
    energy_weight, proximal_weight : float
        ``ε_E``, ``ε_P`` (unit-free).
    row_weights : (r,) ndarray, optional  [-, m/rad]
        ``ω`` of each row (:mod:`cbha_inverse.core.actuation.effectors`; default all 1).

    Returns
    -------
    QPMatrices

    """
    weights = (np.ones(w_ea.shape[0]) if row_weights is None
               else np.ascontiguousarray(row_weights, dtype=float))
    hessian, tracking, weighted_w = qp_kernels.qp_hessians(
        w_ea, w_aa, scale, float(energy_weight), float(proximal_weight), weights)
    return QPMatrices(hessian, tracking, weighted_w, scale, proximal_weight)


def qp_problem(matrices, delta_free, previous, lower_bounds, upper_bounds, rate_limit=None):
    """
    Return the QP of one tick from its matrices and the current free gap.

    Parameters
    ----------
    matrices : QPMatrices
        From :func:`qp_matrices`.
    delta_free : (r,) ndarray  [m, rad]
        ``δ_e^free``.
    previous : (m,) ndarray
        ``λ_prev``.
    lower_bounds, upper_bounds : (m,) ndarray
        Actuator bounds.
    rate_limit : (m,) ndarray or None
        Largest change per tick.

    Returns
    -------
    QPProblem

    """
    rate = np.full(previous.size, np.inf) if rate_limit is None else rate_limit
    gradient, lower, upper, x_prev, tracking_gradient = qp_kernels.qp_vectors(
        matrices.weighted_w, float(matrices.proximal_weight), matrices.scale, delta_free,
        previous, lower_bounds, upper_bounds, rate)
    return QPProblem(matrices.hessian, gradient, lower, upper, matrices.scale, x_prev,
                     matrices.tracking_hessian, tracking_gradient)


# proxsuite's status names -> this package's
_STATUS = {
    'PROXQP_SOLVED': 'solved',
    'PROXQP_MAX_ITER_REACHED': 'max_iterations',
    'PROXQP_PRIMAL_INFEASIBLE': 'primal_infeasible',
    'PROXQP_SOLVED_CLOSEST_PRIMAL_FEASIBLE': 'closest_primal_feasible',
    'PROXQP_DUAL_INFEASIBLE': 'dual_infeasible',
    'PROXQP_NOT_RUN': 'not_run',
}

_INFINITY = 1e20
"""proxsuite's infinite bound."""

_ACTIVE_SET_STATUS = {
    qp_kernels.SOLVED: 'solved',
    qp_kernels.MAX_ITERATIONS: 'max_iterations',
    qp_kernels.SINGULAR: 'singular',
}


class QPSolution(NamedTuple):
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


def _dense_qp(n_variables, n_inequalities, eps_abs, max_iterations):
    """Return a proxsuite dense QP with a box and ``n_inequalities`` general rows, quiet."""
    qp = proxsuite.proxqp.dense.QP(n_variables, 0, n_inequalities, True)
    qp.settings.eps_abs = eps_abs
    qp.settings.eps_rel = 0.0
    qp.settings.max_iter = max_iterations
    qp.settings.verbose = False
    return qp


def _first_solve(qp, *data):
    """Initialise a proxsuite QP with ``data`` and solve; later solves warm-start from it."""
    qp.init(*data)
    qp.solve()
    # warm start only once a previous result exists (proxsuite 0.8 crashes otherwise)
    qp.settings.initial_guess = proxsuite.proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT


def _outcome(qp, m):
    """Return the first ``m`` variables of a proxsuite solve, its status, iterations and ok."""
    info = qp.results.info
    status = _STATUS.get(info.status.name, info.status.name)
    x = qp.results.x[:m]
    return x, status, int(info.iter), status == 'solved' and bool(np.isfinite(x.sum()))


class ProxsuiteQP:
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
        self._qp = _dense_qp(self.n_actuators, 0, self.eps_abs, self.max_iterations)
        self._initialised = False

    def solve(self, problem, same_hessian=False):
        """
        Solve a :class:`QPProblem`.

        Parameters
        ----------
        problem : QPProblem
            The normalised QP.
        same_hessian : bool
            The Hessian is the one of the previous solve (only ``g`` and the box are sent).

        Returns
        -------
        QPSolution
            The solution and proxsuite's status (always checked by the caller).

        """
        qp = self._qp
        if not self._initialised:
            _first_solve(qp, problem.hessian, problem.gradient, None, None, None, None, None,
                         problem.lower, problem.upper)
            self._initialised = True
        elif same_hessian:
            qp.update(g=problem.gradient, l_box=problem.lower, u_box=problem.upper,
                      update_preconditioner=False)
            qp.solve()
        else:
            qp.update(H=problem.hessian, g=problem.gradient, l_box=problem.lower,
                      u_box=problem.upper, update_preconditioner=False)
            qp.solve()
        x, status, iterations, ok = _outcome(qp, self.n_actuators)
        if not ok:
            self.reset()
            x = problem.previous
        x = np.minimum(np.maximum(x, problem.lower), problem.upper)
        if ok:
            x = polish(problem, x)
        return QPSolution(x, status, iterations, ok)


class RowsQP:
    """
    The actuation QP with inequality rows ``A x + b ≥ 0`` [m], each with a slack, by proxsuite.

    The obstacle rows of a tick (:mod:`cbha_inverse.core.inverse.obstacle_rows`) in the
    dimensionless ``x = λ / σ``: ``A = G σ``, ``b = c``. A row that cannot hold (the arm pushed
    against an obstacle by its bounds or by other rows) must not make the QP infeasible: each
    row ``i`` has a slack ``s_i ≥ 0`` [m], ``A_i x + b_i + s_i ≥ 0``, charged
    ``½ ρ s_i² / ν`` (``ν`` the tracking term's normaliser: a metre of slack costs ``ρ`` times a
    metre of tracking gap). In proxsuite's variables the slack is ``s = ℓ t``,
    ``ℓ = sqrt(ν / ρ)``, so ``t`` enters the Hessian with 1. The box of ``x`` stays a box,
    ``t ≥ 0`` joins it. One proxsuite object per number of rows, warm-started from its previous
    result. The compiled tick solves the same problem with the slack eliminated, exactly, by an
    active set over the rows (:func:`cbha_inverse.core._kernels.qp.rows_qp_into`); this class
    serves the ``proxsuite`` and ``gauss_seidel`` solver options and the fallback when that
    active set fails.

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
        """Start without proxsuite objects."""
        self.n_actuators = int(n_actuators)
        self.eps_abs = float(eps_abs)
        self.max_iterations = int(max_iterations)
        self.reset()

    def reset(self):
        """Forget the warm starts."""
        self._qps = {}

    def _qp(self, rows):
        """Return the proxsuite object of ``rows`` rows and whether it was solved before."""
        found = self._qps.get(rows)
        if found is None:
            qp = _dense_qp(self.n_actuators + rows, rows, self.eps_abs, self.max_iterations)
            found = self._qps[rows] = [qp, False]
        return found

    def solve(self, problem, rows, constant, normaliser, weight):
        """
        Solve a :class:`QPProblem` with the rows ``rows x + constant ≥ 0``, slackened.

        Parameters
        ----------
        problem : QPProblem
            The normalised box QP.
        rows : (r, m) ndarray  [m]
            ``A``.
        constant : (r,) ndarray  [m]
            ``b``.
        normaliser : float  [m²]
            ``ν``.
        weight : float  [-]
            ``ρ``.

        Returns
        -------
        solution : QPSolution
            ``x`` clipped into the box (the previous actuation when proxsuite failed).
        slack : (r,) ndarray  [m]
            ``max(0, -(A x + b))`` at the returned ``x``: how far each row is violated.

        """
        m, r = self.n_actuators, constant.size
        scale = math.sqrt(normaliser / weight)
        hessian = np.zeros((m + r, m + r))
        hessian[:m, :m] = problem.hessian
        hessian[m:, m:] = np.eye(r)
        gradient = np.concatenate((problem.gradient, np.zeros(r)))
        inequality = np.hstack((rows, scale * np.eye(r)))
        lower = np.concatenate((problem.lower, np.zeros(r)))
        upper = np.concatenate((problem.upper, np.full(r, _INFINITY)))
        below, above = -constant, np.full(r, _INFINITY)
        found = self._qp(r)
        qp = found[0]
        if not found[1]:
            _first_solve(qp, hessian, gradient, None, None, inequality, below, above, lower,
                         upper)
            found[1] = True
        else:
            qp.update(H=hessian, g=gradient, C=inequality, l=below, u=above, l_box=lower,
                      u_box=upper, update_preconditioner=False)
            qp.solve()
        x, status, iterations, ok = _outcome(qp, m)
        if not ok:
            del self._qps[r]
            x = problem.previous
        x = np.minimum(np.maximum(x, problem.lower), problem.upper)
        slack = np.maximum(-(rows @ x + constant), 0.0)
        return QPSolution(x, status, iterations, ok), slack


class ActiveSetQP:
    """
    Exact box-QP solver for small problems (m ≲ 30): principal pivoting on the active set.

    Each iteration fixes the variables of the current active set at their bounds and solves the
    others from the KKT equations (a Cholesky solve of the free block of the SPD Hessian); the
    variables that leave the box become active and the active ones whose multiplier has the wrong
    sign become free (block pivoting for the first iterations, then one variable at a time,
    Murty's rule, which terminates for positive definite Hessians). The active set of the previous
    tick is the warm start, so a tracking tick usually takes one iteration. The result satisfies
    the KKT conditions to round-off (checked); if not within ``max_iterations``, ``ok`` is False
    and the caller falls back to proxsuite. The iteration is the compiled kernel
    :func:`cbha_inverse.core._kernels.qp.active_set_box_qp`.

    Parameters
    ----------
    n_actuators : int
        ``m``.
    max_iterations : int
        Iteration limit (default ``4 m + 10``).
    state : (m,) int8 ndarray, optional
        The buffer that holds the warm start (the solver's tick data shares it with its
        compiled tick); default: its own.

    """

    def __init__(self, n_actuators, max_iterations=None, state=None):
        """Start with every variable free."""
        self.n_actuators = int(n_actuators)
        self.max_iterations = (4 * self.n_actuators + 10 if max_iterations is None
                               else int(max_iterations))
        self._state = np.zeros(self.n_actuators, dtype=np.int8) if state is None else state
        self.reset()

    def reset(self):
        """Forget the warm start (active set)."""
        self._state[:] = 0

    def solve(self, problem):
        """
        Solve a :class:`QPProblem` exactly.

        Parameters
        ----------
        problem : QPProblem
            The normalised QP (SPD Hessian).

        Returns
        -------
        QPSolution
            ``status`` ``'solved'`` (KKT conditions hold) or ``'max_iterations'`` /
            ``'singular'`` (``ok`` False, ``x`` the previous actuation clipped into the box).

        """
        x, code, iterations, state = qp_kernels.active_set_box_qp(
            problem.hessian, problem.gradient, problem.lower, problem.upper, self._state,
            self.max_iterations)
        if code == qp_kernels.SOLVED:
            self._state[:] = state
            return QPSolution(x, 'solved', iterations, True)
        self.reset()
        x = np.minimum(np.maximum(problem.previous, problem.lower), problem.upper)
        return QPSolution(x, _ACTIVE_SET_STATUS[code], iterations, False)


def polish(problem, x, tolerance=1e-4):
    """
    Refine an approximate box-QP solution on its active set (exact KKT point if it is one).

    proxsuite's augmented-Lagrangian iterate leaves the bound-active variables a little inside
    the box (about ``sqrt(eps)``). Fixing the variables within ``tolerance`` of a bound whose
    gradient pushes outward and solving the equality-constrained problem of the others gives the
    exact solution (the KKT point of that active set); it is accepted only if it is feasible and
    its active multipliers have the right sign, otherwise ``x`` is returned unchanged. Without
    active bounds proxsuite's iterate is returned as is.

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
    y, accepted = qp_kernels.polish_box_qp(problem.hessian, problem.gradient, problem.lower,
                                           problem.upper, x, tolerance)
    return y if accepted else x


def projected_gauss_seidel(problem, x0=None, max_iterations=500, tolerance=1e-10):
    """
    Solve the box QP by projected Gauss-Seidel, as the paper's solver does (Sec. IV).

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
    return qp_kernels.bounds_binding(problem.tracking_hessian, problem.tracking_gradient,
                                     problem.lower, problem.upper, x, tolerance)
