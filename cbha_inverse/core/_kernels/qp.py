"""
Compiled kernels of the actuation QP (paper eq. 13): its matrices, the active-set box-QP solver.

:func:`rows_qp_into` solves the QP with slackened rows (the obstacle rows,
``docs/obstacles.md``) by an active set over the rows around the box solver.

The QP of a control tick is tiny (``m`` = 6..16 actuators) and solved every tick, so a numpy
implementation spends its time in call overhead (dozens of 1-3 us calls) rather than arithmetic.
These kernels hold the arithmetic of :mod:`cbha_inverse.core.inverse.qp` (``qp_matrices``,
``qp_problem``, ``ActiveSetQP``, ``polish`` and ``binding_bounds``) as plain loops compiled by
numba (``cache=True``: compiled once, later processes load the machine code
from ``__pycache__``). The public functions there keep the documentation and the result types;
the equations are cited in their docstrings. Small dense solves use the hand-written Cholesky
factorisation of :func:`solve_free_block` (``m ≲ 30``: no LAPACK call overhead).
"""

import numba
import numpy as np


SOLVED = 0
"""Status code of :func:`active_set_box_qp`: the KKT conditions hold."""
MAX_ITERATIONS = 1
"""Status code of :func:`active_set_box_qp`: the iteration limit was reached."""
SINGULAR = 2
"""Status code of :func:`active_set_box_qp`: a free block is not positive definite."""
ROWS_UNSETTLED = 3
"""Status code of :func:`rows_qp`: the rows' states still disagree with their signs after the
round limit."""

_BOUND_SLACK = 1e-13
"""Box violation (dimensionless) tolerated before a free variable is made active (round-off)."""


@numba.njit(cache=True)
def qp_hessians(w_ea, w_aa, scale, energy_weight, proximal_weight, row_weights):
    """
    Return the normalised Hessian parts of the actuation QP.

    With the row weights ``Ω = diag(ω)`` (:mod:`cbha_inverse.core.actuation.effectors`),
    ``W = Ω W_ea diag(σ)``, ``T = Wᵀ W``, ``ν = trace(T) / m`` (1 if not positive),
    ``E = diag(σ) W_aa diag(σ)`` and ``ν_E = trace(E) / m``::

        tracking = T / ν,   weighted_w = Ω W / ν,
        hessian  = T / ν + ε_P I + ε_E (E + Eᵀ) / (2 ν_E)      (energy term only if ν_E, ε_E > 0)

    so that the tracking gradient ``weighted_wᵀ δ_free`` and ``tracking`` are those of
    ``½ ‖Ω (W_ea λ + δ_free)‖² / ν``.

    Parameters
    ----------
    w_ea : (r, m) ndarray of float64
        Effector-actuator compliance ``W_ea`` (``r`` rows: position and rotational).
    w_aa : (m, m) ndarray of float64
        Actuator-actuator compliance ``W_aa``.
    scale : (m,) ndarray of float64
        ``σ``.
    energy_weight, proximal_weight : float
        ``ε_E``, ``ε_P`` (unit-free).
    row_weights : (r,) ndarray of float64
        ``ω`` of each row of ``W_ea`` (all 1: the paper's tracking term).

    Returns
    -------
    hessian : (m, m) ndarray
        Full normalised Hessian (exactly symmetric).
    tracking : (m, m) ndarray
        Normalised tracking Hessian ``T / ν`` (exactly symmetric).
    weighted_w : (r, m) ndarray
        ``Ω W / ν``.

    """
    rows, m = w_ea.shape
    hessian, tracking, w = np.empty((m, m)), np.empty((m, m)), np.empty((rows, m))
    qp_hessians_into(w_ea, w_aa, scale, energy_weight, proximal_weight, row_weights, hessian,
                     tracking, w)
    return hessian, tracking, w


@numba.njit(cache=True)
def qp_hessians_into(w_ea, w_aa, scale, energy_weight, proximal_weight, row_weights, hessian,
                     tracking, w):
    """
    :func:`qp_hessians` into preallocated ``hessian``, ``tracking`` (m, m) and ``w`` (r, m).

    ``w_ea`` must not be ``w`` (it is read while ``w`` is written). Returns the normaliser
    ``ν`` [m², the rows' units squared].
    """
    rows, m = w_ea.shape
    for r in range(rows):
        for j in range(m):
            w[r, j] = row_weights[r] * w_ea[r, j] * scale[j]
    # upper triangle of Wᵀ W, accumulated row by row of W (contiguous inner loop)
    tracking[:, :] = 0.0
    for r in range(rows):
        for i in range(m):
            w_ri = w[r, i]
            for j in range(i, m):
                tracking[i, j] += w_ri * w[r, j]
    norm = 0.0
    for i in range(m):
        norm += tracking[i, i]
    norm /= m
    if not norm > 0.0:
        norm = 1.0
    for r in range(rows):
        for j in range(m):
            w[r, j] = w[r, j] * row_weights[r] / norm
    energy_norm = 0.0
    for i in range(m):
        energy_norm += w_aa[i, i] * scale[i] * scale[i]
    energy_norm /= m
    energy_factor = 0.0
    if energy_norm > 0.0 and energy_weight > 0.0:
        energy_factor = 0.5 * energy_weight / energy_norm
    for i in range(m):
        for j in range(i, m):
            t = tracking[i, j] / norm
            h = t + energy_factor * (w_aa[i, j] + w_aa[j, i]) * (scale[i] * scale[j])
            tracking[i, j] = t
            tracking[j, i] = t
            hessian[i, j] = h
            hessian[j, i] = h
        hessian[i, i] += proximal_weight
    return norm


@numba.njit(cache=True)
def qp_vectors(weighted_w, proximal_weight, scale, delta_free, previous, lower_bounds,
               upper_bounds, rate_limit):
    """
    Return the target-dependent vectors of one tick's QP.

    ``x_prev = λ_prev / σ``, ``t = weighted_wᵀ δ_free``, ``g = t - ε_P x_prev`` and the box
    ``[lb / σ, ub / σ]``, intersected with ``x_prev ± rate / σ`` when a rate limit is given.

    Parameters
    ----------
    weighted_w : (r, m) ndarray of float64
        ``Ω² W_ea σ / ν`` from :func:`qp_hessians`.
    proximal_weight : float
        ``ε_P``.
    scale : (m,) ndarray of float64
        ``σ``.
    delta_free : (r,) ndarray of float64  [m, rad]
        ``δ_e^free``.
    previous : (m,) ndarray of float64
        ``λ_prev``.
    lower_bounds, upper_bounds : (m,) ndarray of float64
        Actuator bounds.
    rate_limit : (m,) ndarray of float64
        Largest change per tick (``inf``: none).

    Returns
    -------
    gradient, lower, upper, x_prev, tracking_gradient : (m,) ndarray
        The QP's gradient and box, ``x_prev`` and the tracking part ``t`` of the gradient.

    """
    m = weighted_w.shape[1]
    gradient, lower, upper = np.empty(m), np.empty(m), np.empty(m)
    x_prev, tracking_gradient = np.empty(m), np.empty(m)
    qp_vectors_into(weighted_w, proximal_weight, scale, delta_free, previous, lower_bounds,
                    upper_bounds, rate_limit, gradient, lower, upper, x_prev, tracking_gradient)
    return gradient, lower, upper, x_prev, tracking_gradient


@numba.njit(cache=True)
def qp_vectors_into(weighted_w, proximal_weight, scale, delta_free, previous, lower_bounds,
                    upper_bounds, rate_limit, gradient, lower, upper, x_prev, tracking_gradient):
    """:func:`qp_vectors` into preallocated (m,) arrays (the order of its results)."""
    rows, m = weighted_w.shape
    for j in range(m):
        x_prev[j] = previous[j] / scale[j]
        s = 0.0
        for r in range(rows):
            s += weighted_w[r, j] * delta_free[r]
        tracking_gradient[j] = s
        gradient[j] = s - proximal_weight * x_prev[j]
        lower[j] = lower_bounds[j] / scale[j]
        upper[j] = upper_bounds[j] / scale[j]
        step = rate_limit[j] / scale[j]
        lower[j] = max(lower[j], x_prev[j] - step)
        upper[j] = min(upper[j], x_prev[j] + step)


@numba.njit(cache=True)
def solve_free_block(h, g, x, free):
    """
    Solve the stationarity equations of the free variables with the others fixed, in place.

    ``H_ff x_f = -g_f - H_fb x_b`` by a Cholesky factorisation of ``H_ff`` (LAPACK ``dposv``'s
    algorithm and failure test, without its call overhead for the small blocks of the QP).

    Parameters
    ----------
    h : (m, m) ndarray of float64
        Symmetric Hessian (only the free rows and columns are read).
    g : (m,) ndarray of float64
        Gradient.
    x : (m,) ndarray of float64
        Input: the fixed values ``x_b`` of the bound variables; output: ``x_f`` written.
    free : (m,) ndarray of bool
        The free variables.

    Returns
    -------
    bool
        Whether ``H_ff`` is positive definite and ``x_f`` finite (else ``x_f`` is undefined).

    """
    m = x.size
    return solve_free_block_into(h, g, x, free, np.empty(m, dtype=np.int64), np.empty((m, m)),
                                 np.empty(m))


@numba.njit(cache=True)
def solve_free_block_into(h, g, x, free, index, a, y):
    """
    Solve as :func:`solve_free_block` does, with its workspace given.

    The workspace: ``index`` (m,) int64, ``a`` (m, m), ``y`` (m,). The free block ``H_ff`` and
    its factor use the top-left ``n x n`` corner of ``a``.
    """
    m = x.size
    n = 0
    for i in range(m):
        if free[i]:
            index[n] = i
            n += 1
    for p in range(n):
        i = index[p]
        s = -g[i]
        for j in range(m):
            if not free[j]:
                s -= h[i, j] * x[j]
        y[p] = s
        for q in range(n):
            a[p, q] = h[i, index[q]]
    # lower Cholesky factor a = L Lᵀ, column by column (L stored in the lower triangle)
    for j in range(n):
        d = a[j, j]
        for k in range(j):
            d -= a[j, k] * a[j, k]
        if not d > 0.0:
            return False
        d = np.sqrt(d)
        a[j, j] = d
        for i in range(j + 1, n):
            s = a[i, j]
            for k in range(j):
                s -= a[i, k] * a[j, k]
            a[i, j] = s / d
    for i in range(n):
        s = y[i]
        for k in range(i):
            s -= a[i, k] * y[k]
        y[i] = s / a[i, i]
    for i in range(n - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, n):
            s -= a[k, i] * y[k]
        y[i] = s / a[i, i]
    for p in range(n):
        if not np.isfinite(y[p]):
            return False
        x[index[p]] = y[p]
    return True


@numba.njit(cache=True)
def _gradient_entry(h, g, x, i):
    """Return ``(H x + g)_i``."""
    s = g[i]
    for j in range(x.size):
        s += h[i, j] * x[j]
    return s


@numba.njit(cache=True)
def active_set_box_qp(h, g, lower, upper, state, max_iterations):
    """
    Solve ``min ½ xᵀ H x + gᵀ x`` s.t. ``lower ≤ x ≤ upper`` by principal pivoting.

    ``state`` holds -1 (at the lower bound), +1 (at the upper bound) or 0 (free) per variable.
    Each iteration fixes the active variables at their bounds, solves the free ones
    (:func:`solve_free_block`) and pivots the violators: free variables outside the box
    (by more than 1e-13) become active at the violated bound, active ones whose multiplier has
    the wrong sign (gradient beyond ``1e-12 (2 + max|g|)``) become free. All violators are
    pivoted in iterations 1-3 (block pivoting), then only the first one (Murty's rule, finite
    termination for positive definite ``H``). No violator is the KKT conditions.

    Parameters
    ----------
    h : (m, m) ndarray of float64
        Symmetric positive definite Hessian (normalised, ``|H| ~ 1``).
    g : (m,) ndarray of float64
        Gradient.
    lower, upper : (m,) ndarray of float64
        Box, ``lower ≤ upper``.
    state : (m,) ndarray of int8
        Warm start (active set of the previous solve); not modified.
    max_iterations : int
        Iteration limit.

    Returns
    -------
    x : (m,) ndarray
        The solution clipped into the box (undefined unless the status is :data:`SOLVED`).
    status : int
        :data:`SOLVED`, :data:`MAX_ITERATIONS` or :data:`SINGULAR`.
    iterations : int
        Iterations done.
    state : (m,) ndarray of int8
        The final active set.

    """
    m = g.size
    state = state.copy()
    x = np.empty(m)
    status, iterations = active_set_box_qp_into(
        h, g, lower, upper, state, max_iterations, x, np.empty(m, dtype=np.bool_),
        np.empty(m, dtype=np.int8), np.empty(m, dtype=np.int64), np.empty((m, m)), np.empty(m))
    return x, status, iterations, state


@numba.njit(cache=True)
def active_set_box_qp_into(h, g, lower, upper, state, max_iterations, x, free, pivot, index,
                           a, y):
    """
    :func:`active_set_box_qp` in place: ``state`` is updated, ``x`` (m,) written.

    ``free`` (m,) bool, ``pivot`` (m,) int8 and the workspace ``index``, ``a``, ``y`` of
    :func:`solve_free_block_into` are given. Returns ``(status, iterations)``.
    """
    m = g.size
    g_max = 0.0
    for i in range(m):
        g_max = max(g_max, abs(g[i]))
    # the problem is normalised (|H| ~ 1): absolute tolerance on the multipliers
    tolerance = 1e-12 * (2.0 + g_max)
    for iteration in range(1, max_iterations + 1):
        for i in range(m):
            free[i] = state[i] == 0
            x[i] = lower[i] if state[i] < 0 else upper[i]
        if not solve_free_block_into(h, g, x, free, index, a, y):
            return SINGULAR, iteration
        # pivot[i]: the new state of a violating variable, 2 for none
        first = -1
        for i in range(m):
            pivot[i] = 2
            if free[i]:
                if x[i] < lower[i] - _BOUND_SLACK:
                    pivot[i] = -1
                elif x[i] > upper[i] + _BOUND_SLACK:
                    pivot[i] = 1
            else:
                grad = _gradient_entry(h, g, x, i)
                if (state[i] < 0 and grad < -tolerance) or (state[i] > 0 and grad > tolerance):
                    pivot[i] = 0
            if first < 0 and pivot[i] != 2:
                first = i
        if first < 0:
            for i in range(m):
                x[i] = min(max(x[i], lower[i]), upper[i])
            return SOLVED, iteration
        if iteration > 3:
            state[first] = pivot[first]
        else:
            for i in range(m):
                if pivot[i] != 2:
                    state[i] = pivot[i]
    return MAX_ITERATIONS, max_iterations


@numba.njit(cache=True)
def polish_box_qp(h, g, lower, upper, x, tolerance):
    """
    Return the KKT point of the active set that an approximate box-QP solution suggests.

    Variables within ``tolerance`` of a bound whose gradient ``H x + g`` pushes outward are fixed
    there, the others solved from the stationarity equations (:func:`solve_free_block`). The
    result is accepted if it lies in the box and the fixed variables' gradients keep their sign.

    Parameters
    ----------
    h : (m, m) ndarray of float64
        Symmetric positive definite Hessian.
    g : (m,) ndarray of float64
        Gradient.
    lower, upper : (m,) ndarray of float64
        Box.
    x : (m,) ndarray of float64
        Approximate solution inside the box.
    tolerance : float
        Distance to a bound below which a variable is tried as active.

    Returns
    -------
    y : (m,) ndarray
        The refined solution (undefined if not ``accepted``).
    accepted : bool
        Whether ``y`` was found and is the KKT point (else ``x`` stands).

    """
    m = x.size
    y = x.copy()
    at_bound = np.zeros(m, dtype=np.int8)
    n_active = 0
    for i in range(m):
        near_lower = x[i] - lower[i] < tolerance
        near_upper = upper[i] - x[i] < tolerance
        if near_lower or near_upper:
            grad = _gradient_entry(h, g, x, i)
            if near_lower and grad > 0.0:
                at_bound[i] = -1
                y[i] = lower[i]
            elif near_upper and grad < 0.0:
                at_bound[i] = 1
                y[i] = upper[i]
            n_active += at_bound[i] != 0
    if n_active == 0:
        return y, False
    free = at_bound == 0
    if n_active < m and not solve_free_block(h, g, y, free):
        return y, False
    for i in range(m):
        if not lower[i] <= y[i] <= upper[i]:
            return y, False
        if at_bound[i] != 0:
            grad = _gradient_entry(h, g, y, i)
            if (at_bound[i] < 0 and not grad >= 0.0) or (at_bound[i] > 0 and not grad <= 0.0):
                return y, False
    return y, True


@numba.njit(cache=True)
def bounds_binding(tracking_hessian, tracking_gradient, lower, upper, x, tolerance):
    """
    Return which variables sit on a bound that the tracking gradient pushes against.

    ``x_i ≤ lower_i + tol`` and ``(T x + t)_i > tol``, or ``x_i ≥ upper_i - tol`` and
    ``(T x + t)_i < -tol``.

    Parameters
    ----------
    tracking_hessian : (m, m) ndarray of float64
        ``T``.
    tracking_gradient : (m,) ndarray of float64
        ``t``.
    lower, upper : (m,) ndarray of float64
        Box.
    x : (m,) ndarray of float64
        Solution.
    tolerance : float
        Tolerance on the distance to the bound and on the gradient.

    Returns
    -------
    (m,) ndarray of bool
        The binding bounds.

    """
    binding = np.empty(x.size, dtype=np.bool_)
    bounds_binding_into(tracking_hessian, tracking_gradient, lower, upper, x, tolerance, binding)
    return binding


@numba.njit(cache=True)
def bounds_binding_into(tracking_hessian, tracking_gradient, lower, upper, x, tolerance,
                        binding):
    """:func:`bounds_binding` into a preallocated ``binding`` (m,) bool."""
    for i in range(x.size):
        binding[i] = False
        near_lower = x[i] <= lower[i] + tolerance
        near_upper = x[i] >= upper[i] - tolerance
        if near_lower or near_upper:
            grad = _gradient_entry(tracking_hessian, tracking_gradient, x, i)
            binding[i] = (near_lower and grad > tolerance) or (near_upper and grad < -tolerance)


@numba.njit(cache=True)
def rows_qp(h, g, lower, upper, rows, constant, penalty, state, row_on, max_iterations,
            max_rounds):
    """
    Solve the box QP with slackened rows: ``min ½ xᵀ H x + gᵀ x + ½ p Σ max(0, -(A x + b))²``.

    The problem of :class:`cbha_inverse.core.inverse.qp.RowsQP` (``min ½ xᵀ H x + gᵀ x + ½ |t|²``
    over ``lower ≤ x ≤ upper``, ``t ≥ 0``, ``A x + b + ℓ t ≥ 0``) with its slack eliminated: at
    the optimum ``t_i = max(0, -(A_i x + b_i)) / ℓ``, so it is this box QP with a convex
    piecewise-quadratic penalty, ``p = 1 / ℓ²``. With the set ``S`` of the rows "on" (their
    penalty active), the penalised problem is the box QP of

        H_S = H + p Σ_{i∈S} a_i a_iᵀ,     g_S = g + p Σ_{i∈S} b_i a_i,

    solved by :func:`active_set_box_qp_into` (warm-started from ``state``); a row is on when
    ``A_i x + b_i < 0`` at that solution and off when it is positive: the rows whose state
    disagrees are flipped (all of them in rounds 1-3, then the first one) and the box QP solved
    again, until every state agrees with its row's sign within round-off (``1e-12`` of the
    row's terms). Then ``x`` satisfies the KKT conditions of the penalised problem, which are
    those of the box QP of ``H_S``, ``g_S``.

    Parameters
    ----------
    h : (m, m) ndarray
        Symmetric positive definite Hessian (normalised).
    g : (m,) ndarray
        Gradient.
    lower, upper : (m,) ndarray
        Box.
    rows : (r, m) ndarray
        ``A``.
    constant : (r,) ndarray
        ``b``.
    penalty : float
        ``p = 1 / ℓ²`` (> 0).
    state : (m,) ndarray of int8
        Warm start of the box's active set; not modified.
    row_on : (r,) ndarray of bool
        Warm start of the rows' states; not modified.
    max_iterations : int
        Iteration limit of each box QP.
    max_rounds : int
        Limit of the box QPs solved.

    Returns
    -------
    x : (m,) ndarray
        The solution clipped into the box (undefined unless the status is :data:`SOLVED`).
    status : int
        :data:`SOLVED`, :data:`ROWS_UNSETTLED`, or the box QP's :data:`MAX_ITERATIONS` or
        :data:`SINGULAR`.
    iterations : int
        Active-set iterations over all rounds.
    rounds : int
        Box QPs solved.
    state : (m,) ndarray of int8
        The final active set of the box.
    row_on : (r,) ndarray of bool
        The final rows' states.
    values : (r,) ndarray
        ``A x + b`` at the solution.

    """
    m, r = g.size, constant.size
    state, row_on = state.copy(), row_on.copy()
    x, values = np.empty(m), np.empty(r)
    status, iterations, rounds = rows_qp_into(
        h, g, lower, upper, rows, constant, penalty, state, row_on, max_iterations,
        max_rounds, x, np.empty(m, dtype=np.bool_), np.empty(m, dtype=np.int8),
        np.empty(m, dtype=np.int64), np.empty((m, m)), np.empty(m), np.empty((m, m)),
        np.empty(m), values)
    return x, status, iterations, rounds, state, row_on, values


@numba.njit(cache=True)
def rows_qp_into(h, g, lower, upper, rows, constant, penalty, state, row_on, max_iterations,
                 max_rounds, x, free, pivot, index, a, y, penalised_h, penalised_g, values):
    """
    :func:`rows_qp` in place: ``state`` and ``row_on`` are updated, ``x``, ``values`` written.

    The workspace of :func:`active_set_box_qp_into` (``free``, ``pivot``, ``index``, ``a``,
    ``y``) and ``penalised_h`` (m, m), ``penalised_g`` (m,): ``H_S``, ``g_S``. Returns
    ``(status, iterations, rounds)``.
    """
    iterations = 0
    for rounds in range(1, max_rounds + 1):
        penalised_qp_into(h, g, rows, constant, penalty, row_on, penalised_h, penalised_g)
        status, done = active_set_box_qp_into(penalised_h, penalised_g, lower, upper, state,
                                              max_iterations, x, free, pivot, index, a, y)
        iterations += done
        if status != SOLVED:
            return status, iterations, rounds
        first = -1
        for i in range(constant.size):
            value, size = constant[i], abs(constant[i])
            for j in range(x.size):
                value += rows[i, j] * x[j]
                size += abs(rows[i, j] * x[j])
            values[i] = value
            round_off = 1e-12 * size
            if (row_on[i] and value > round_off) or (not row_on[i] and value < -round_off):
                if first < 0:
                    first = i
                if rounds <= 3:
                    row_on[i] = not row_on[i]
        if first < 0:
            return SOLVED, iterations, rounds
        if rounds > 3:
            row_on[first] = not row_on[first]
    return ROWS_UNSETTLED, iterations, max_rounds


@numba.njit(cache=True)
def penalised_qp_into(h, g, rows, constant, penalty, row_on, penalised_h, penalised_g):
    """
    Write ``H_S = H + p Σ_{i∈S} a_i a_iᵀ`` and ``g_S = g + p Σ_{i∈S} b_i a_i`` (:func:`rows_qp`).

    Parameters
    ----------
    h : (m, m) ndarray
        ``H``.
    g : (m,) ndarray
        ``g``.
    rows : (r, m) ndarray
        ``A`` (row ``i``: ``a_iᵀ``).
    constant : (r,) ndarray
        ``b``.
    penalty : float
        ``p``.
    row_on : (r,) ndarray of bool
        ``S``.
    penalised_h : (m, m) ndarray
        Receives ``H_S`` (exactly symmetric).
    penalised_g : (m,) ndarray
        Receives ``g_S``.

    """
    m = g.size
    for i in range(m):
        penalised_g[i] = g[i]
        for j in range(m):
            penalised_h[i, j] = h[i, j]
    for k in range(constant.size):
        if not row_on[k]:
            continue
        for i in range(m):
            weighted = penalty * rows[k, i]
            penalised_g[i] += weighted * constant[k]
            for j in range(i, m):
                penalised_h[i, j] += weighted * rows[k, j]
    for i in range(m):
        for j in range(i + 1, m):
            penalised_h[j, i] = penalised_h[i, j]
