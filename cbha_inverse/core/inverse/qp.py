"""
Solvers of the box-constrained actuation QP (paper eq. 13): proxsuite and projected Gauss-Seidel.

The problem itself (:class:`cbha_inverse.core.inverse.qp_problem.QPProblem`) is built in
:mod:`cbha_inverse.core.inverse.qp_problem`; here it is solved, polished onto its active set
and checked for saturation. proxsuite's status is always returned to the caller.
"""

from typing import NamedTuple

from cbha_inverse.core._kernels import qp as qp_kernels
import numpy as np
import proxsuite


_STATUS = {
    'PROXQP_SOLVED': 'solved',
    'PROXQP_MAX_ITER_REACHED': 'max_iterations',
    'PROXQP_PRIMAL_INFEASIBLE': 'primal_infeasible',
    'PROXQP_SOLVED_CLOSEST_PRIMAL_FEASIBLE': 'closest_primal_feasible',
    'PROXQP_DUAL_INFEASIBLE': 'dual_infeasible',
    'PROXQP_NOT_RUN': 'not_run',
}

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
            qp.init(problem.hessian, problem.gradient, None, None, None, None, None,
                    problem.lower, problem.upper)
            qp.solve()
            # warm start only once a previous result exists (proxsuite 0.8 crashes otherwise)
            qp.settings.initial_guess = (
                proxsuite.proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT)
            self._initialised = True
        elif same_hessian:
            qp.update(g=problem.gradient, l_box=problem.lower, u_box=problem.upper,
                      update_preconditioner=False)
            qp.solve()
        else:
            qp.update(H=problem.hessian, g=problem.gradient, l_box=problem.lower,
                      u_box=problem.upper, update_preconditioner=False)
            qp.solve()
        results = qp.results
        info = results.info
        status = _STATUS.get(info.status.name, info.status.name)
        x = results.x
        ok = status == 'solved' and bool(np.isfinite(x.sum()))
        if not ok:
            self.reset()
            x = problem.previous
        x = np.minimum(np.maximum(x, problem.lower), problem.upper)
        if ok:
            x = polish(problem, x)
        return QPSolution(x, status, int(info.iter), ok)


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

    """

    def __init__(self, n_actuators, max_iterations=None):
        """Start with every variable free."""
        self.n_actuators = int(n_actuators)
        self.max_iterations = (4 * self.n_actuators + 10 if max_iterations is None
                               else int(max_iterations))
        self.reset()

    def reset(self):
        """Forget the warm start (active set)."""
        self._state = np.zeros(self.n_actuators, dtype=np.int8)

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
            self._state = state
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
    return qp_kernels.bounds_binding(problem.tracking_hessian, problem.tracking_gradient,
                                     problem.lower, problem.upper, x, tolerance)
