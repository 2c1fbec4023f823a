"""
The control tick as two compiled entry points over preallocated buffers (`docs/design.md`).

:func:`linearise_tick` is steps 1-2 of :class:`cbha_inverse.core.inverse.solver.InverseSolver`
(links and cables, band assembly, band Cholesky, the multi-RHS solve, the projection onto the
effectors and actuators and the QP matrices); :func:`solve_tick` is steps 3-4 (the QP vectors
from the targets, the active-set box QP, the outcome, the binding bounds, the linear step and the
effector positions). Each calls the kernels of this folder that hold the equations (numba
compiles them into the entry): nothing here is a second copy of their arithmetic. Python crosses
into compiled code once per step instead of once per kernel, and no array is allocated: the
buffers are those of :class:`cbha_inverse.core.inverse.tick_data.TickData`, grouped by shape
into a few stacked arrays so that an entry takes few arguments (numba unboxes every argument at
every call, ~0.1 us each). The rows of the stacks are the constants below.
"""

from cbha_inverse.core._kernels.band import band_cholesky, band_solve, scatter_add
from cbha_inverse.core._kernels.cables import cable_pass_into
from cbha_inverse.core._kernels.links import link_pass_into
from cbha_inverse.core._kernels.projection import (effector_points_into, project_effectors_into,
                                                   tick_outcome_into)
from cbha_inverse.core._kernels.qp import (active_set_box_qp_into, bounds_binding_into,
                                           qp_hessians_into, qp_vectors_into, SOLVED)
from cbha_inverse.core._kernels.retraction import apply_linear_step_into
import numba

# rows of the actuator vectors, (ACTUATOR_ROWS, m): model constants, then the tick's state and
# its workspace
SCALE, LOWER, UPPER, RATE = 0, 1, 2, 3
ACTUATION, PROPOSED, LINEARISED, X, CHANGE, SOLVE = 4, 5, 6, 7, 8, 9
GRADIENT, BOX_LOWER, BOX_UPPER, X_PREVIOUS, TRACKING_GRADIENT = 10, 11, 12, 13, 14
ACTUATOR_ROWS = 15
# matrices (MATRIX_ROWS, m, m): the QP's Hessian and tracking Hessian, W_aa, the solve's factor
HESSIAN, TRACKING, W_AA, FACTOR = 0, 1, 2, 3
MATRIX_ROWS = 4
# effector-actuator matrices (2, 3k, m): W_ea, W_ea σ / ν
W_EA, WEIGHTED_W = 0, 1
# effector gaps (3, 3k): p_e + J_e K⁻¹ r - W_ea λ_prev, δ_free, the predicted gap
OFFSET, DELTA_FREE, GAP = 0, 1, 2
# int8 flags (2, m): the active set (warm start), the pivots
STATE, PIVOT = 0, 1
# code of solve_tick beside the QP's own (SOLVED, MAX_ITERATIONS, SINGULAR)
REJECTED = -1
"""The QP returned a non-finite actuation: the actuation and the state are unchanged."""


@numba.njit(cache=True)
def linearise_tick(positions, rotations, vectors, stiffness, rest_offsets, rest_rotations_t,
                   cavity_wrench, cavity_stiffness, cavity_columns, link_work, external,
                   cable_gains,
                   cable_offsets, cable_frames, cable_spans, cable_points, cable_columns,
                   cable_work, index, slot_weights,
                   counts, values, band, rhs, solved, matrices, effector_matrices, gaps, moved,
                   effector_frames, effector_offsets, levers, weights, cholesky):
    """
    Linearise, factor and project at the given state (steps 1-2 of the tick), in place.

    Runs :func:`~cbha_inverse.core._kernels.links.link_pass_into`,
    :func:`~cbha_inverse.core._kernels.cables.cable_pass_into` (one cable group, or none),
    :func:`~cbha_inverse.core._kernels.band.scatter_add` into the symmetric lower band,
    :func:`~cbha_inverse.core._kernels.band.band_cholesky` and, when it succeeds,
    :func:`project_tick`.

    Parameters
    ----------
    positions : (n + 1, 3) ndarray  [m]
        Frame origins.
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations.
    vectors : (ACTUATOR_ROWS, m) ndarray
        Actuator rows; reads ``ACTUATION`` (``λ_prev``) and ``SCALE``, writes ``LINEARISED``.
    stiffness, rest_offsets, rest_rotations_t, cavity_wrench, cavity_stiffness : ndarray
        The link terms of :func:`~cbha_inverse.core._kernels.links.link_pass`.
    cavity_columns : (n, c) int ndarray
        The nonzero cavity columns of every link
        (:func:`~cbha_inverse.core._kernels.links.nonzero_cavity_columns`).
    link_work, cable_work : ndarray
        Workspace of the link and cable passes.
    external : (6n,) ndarray  [N, N*m]
        Constant external wrenches.
    cable_gains, cable_offsets, cable_frames, cable_columns : ndarray
        The cable group's gains (m_c,), routing points (P, 3) and their frames (P,), actuator
        columns (m_c,) (empty without cables).
    cable_spans : (4, S) int ndarray
        Start point, end point, cable and frame pair of every span.
    cable_points : (2, P) int ndarray
        Cable and moment slot of every routing point.
    index, slot_weights : (V,) ndarray
        The symmetric band's slot and weight of every value.
    counts : (3,) int ndarray
        Numbers of link, cable pair and cable moment values.
    values : (V,) ndarray
        Receives the blocks (links, cable pairs, cable moments).
    band : (6n (kd + 1) + 1,) ndarray
        Receives the symmetric lower band (last slot: the base frame's trash), then its factor.
    rhs : (6n, m + 1) ndarray
        Receives ``[r, J_aᵀ]``.
    solved : (6n, m + 1) ndarray
        Receives ``K⁻¹ [r, J_aᵀ]`` (only when the Cholesky succeeds).
    matrices, effector_matrices, gaps : ndarray
        Receive the projection and the QP matrices (:func:`project_tick`).
    moved : (3k, m + 1) ndarray
        Workspace.
    effector_frames : (k,) int ndarray
        Frame of every effector.
    effector_offsets : (k, 3) ndarray  [m]
        Effector points in their frame's axes.
    levers : (k, 3) ndarray
        Workspace.
    weights : (2,) ndarray
        ``ε_E``, ``ε_P``.
    cholesky : bool
        Factor the symmetric band (else the caller takes the fallback chain at once).

    Returns
    -------
    info : int
        0 if the band Cholesky succeeded (everything written), else nonzero (``rhs`` and
        ``values`` hold the evaluation, for
        :meth:`cbha_inverse.core.system.EquilibriumSystem.fallback_factors`).
    residual_norm : float  [N, N*m]
        ``|r|`` (NaN unless ``info`` is 0).

    """
    actuation = vectors[ACTUATION]
    n = stiffness.shape[0]
    link_end = counts[0]
    pair_end = link_end + counts[1]
    moment_end = pair_end + counts[2]
    link_pass_into(positions, rotations, stiffness, rest_offsets, rest_rotations_t, actuation,
                   cavity_wrench, cavity_stiffness, cavity_columns, rhs,
                   values[:link_end].reshape((n, 12, 12)), False, link_work)
    if cable_frames.size > 0:
        cable_pass_into(positions, rotations, actuation, cable_gains, cable_frames,
                        cable_offsets, cable_spans[0], cable_spans[1], cable_spans[2],
                        cable_points[0], cable_columns, cable_spans[3], cable_points[1], rhs,
                        values[link_end:pair_end].reshape((-1, 12, 12)),
                        values[pair_end:moment_end].reshape((-1, 3, 3)), cable_work)
    for row in range(rhs.shape[0]):
        rhs[row, 0] += external[row]
    scatter_add(index, values, slot_weights, band)
    size = rhs.shape[0]
    factor = band[:-1].reshape((size, (band.size - 1) // size))
    vectors[LINEARISED, :] = actuation
    if not cholesky:
        return -1, float('nan')
    info = band_cholesky(factor)
    if info != 0:
        return info, float('nan')
    solved[:, :] = rhs
    band_solve(factor, solved)
    return 0, project_tick(positions, rotations, vectors, rhs, solved, matrices,
                           effector_matrices, gaps, moved, effector_frames, effector_offsets,
                           levers, weights)


@numba.njit(cache=True)
def project_tick(positions, rotations, vectors, rhs, solved, matrices, effector_matrices, gaps,
                 moved, effector_frames, effector_offsets, levers, weights):
    """
    Project a solved linearisation and form the QP matrices (the end of step 2), in place.

    :func:`~cbha_inverse.core._kernels.projection.project_effectors_into` then
    :func:`~cbha_inverse.core._kernels.qp.qp_hessians_into`. Arguments as
    :func:`linearise_tick` (``vectors[LINEARISED]`` is ``λ_prev``); writes ``W_EA``,
    ``WEIGHTED_W``, ``W_AA``, ``HESSIAN``, ``TRACKING`` and ``OFFSET``.

    Returns
    -------
    float  [N, N*m]
        ``|r|``.

    """
    w_ea = effector_matrices[W_EA]
    w_aa = matrices[W_AA]
    residual_norm = project_effectors_into(
        solved, rhs, positions, rotations, effector_frames, effector_offsets,
        vectors[LINEARISED], w_ea, w_aa, gaps[OFFSET], moved, levers)
    qp_hessians_into(w_ea, w_aa, vectors[SCALE], weights[0], weights[1], matrices[HESSIAN],
                     matrices[TRACKING], effector_matrices[WEIGHTED_W])
    return residual_norm


@numba.njit(cache=True)
def solve_tick(targets, vectors, matrices, effector_matrices, gaps, flags, free,
               index, proximal_weight, max_iterations, tolerance, positions, rotations, solved,
               increments, work, effector_frames, effector_offsets, effector_positions,
               max_rotation, apply_step):
    """
    Solve a tick's QP on a linearisation and apply it (steps 3-4 of the tick), in place.

    Forms ``δ_free`` (the targets are checked by the caller,
    :func:`~cbha_inverse.core._kernels.projection.target_status`) and the QP vectors
    (:func:`~cbha_inverse.core._kernels.qp.qp_vectors_into`), solves the box QP by the active
    set (:func:`~cbha_inverse.core._kernels.qp.active_set_box_qp_into`, warm-started from
    ``flags[STATE]``), then the outcome
    (:func:`~cbha_inverse.core._kernels.projection.tick_outcome_into`) and the binding bounds
    (:func:`~cbha_inverse.core._kernels.qp.bounds_binding_into`). With ``apply_step`` the
    Newton step of the factorization
    (:func:`~cbha_inverse.core._kernels.retraction.apply_linear_step_into`) moves the frames
    and the effector positions of the new state are written.

    Parameters
    ----------
    targets : (k, 3) ndarray  [m]
        Finite effector targets within reach.
    vectors, matrices, effector_matrices, gaps, flags : ndarray
        The stacks of the module docstring, as :func:`linearise_tick` left them. Writes
        ``DELTA_FREE``, the QP vectors, ``X``, ``PROPOSED``, ``GAP``, ``STATE`` and, unless the
        code is :data:`REJECTED` or the QP failed, ``ACTUATION``.
    free : (m,) bool ndarray
        Workspace; on return, the binding bounds (``saturated``) when the QP is solved.
    index : (m,) int64 ndarray
        Workspace.
    proximal_weight : float
        ``ε_P``.
    max_iterations : int
        Active-set iteration limit.
    tolerance : float
        Of the binding bounds.
    positions : (n + 1, 3) ndarray  [m]
        Frame origins (updated with ``apply_step``).
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations (updated with ``apply_step``).
    solved : (6n, m + 1) ndarray
        ``K⁻¹ [r, J_aᵀ]`` of the linearisation.
    increments : (n, 6) ndarray
        Workspace.
    work : (7, 3) ndarray
        Workspace.
    effector_frames : (k,) int ndarray
        Frame of every effector.
    effector_offsets : (k, 3) ndarray  [m]
        Effector points in their frame's axes.
    effector_positions : (k, 3) ndarray  [m]
        Receives the effector positions of the new state (with ``apply_step``).
    max_rotation : float  [rad]
        Largest frame rotation of the step.
    apply_step : bool
        Apply the linear step now (``relinearize_every`` 1).

    Returns
    -------
    code : int
        :data:`~cbha_inverse.core._kernels.qp.SOLVED`, the active set's failure code
        (``MAX_ITERATIONS``, ``SINGULAR``: the QP vectors are written, nothing else) or
        :data:`REJECTED`.
    iterations : int
        Active-set iterations.
    largest_gap : float  [m]
        Largest predicted effector gap.
    largest_move : float
        Largest dimensionless actuation change.
    binding : bool
        Whether some bound binds (the QP is solved and the tick saturated).

    """
    k = targets.shape[0]
    offset, delta_free, gap = gaps[OFFSET], gaps[DELTA_FREE], gaps[GAP]
    for e in range(k):
        for i in range(3):
            delta_free[3 * e + i] = offset[3 * e + i] - targets[e, i]
    weighted_w = effector_matrices[WEIGHTED_W]
    rate = vectors[RATE]
    qp_vectors_into(weighted_w, proximal_weight, vectors[SCALE], delta_free, vectors[ACTUATION],
                    vectors[LOWER], vectors[UPPER], rate, vectors[GRADIENT:])
    hessian = matrices[HESSIAN]
    lower, upper = vectors[BOX_LOWER], vectors[BOX_UPPER]
    x = vectors[X]
    code, iterations = active_set_box_qp_into(
        hessian, vectors[GRADIENT], lower, upper, flags[STATE], max_iterations, x, free,
        flags[PIVOT], index, matrices[FACTOR], vectors[SOLVE])
    if code != SOLVED:
        return code, iterations, 0.0, 0.0, False
    proposed = vectors[PROPOSED]
    largest_gap, largest_move, finite = tick_outcome_into(
        effector_matrices[W_EA], delta_free, vectors[SCALE], x, vectors[X_PREVIOUS],
        vectors[LOWER], vectors[UPPER], proposed, gap)
    if not finite:
        return REJECTED, iterations, largest_gap, largest_move, False
    bounds_binding_into(matrices[TRACKING], vectors[TRACKING_GRADIENT], lower, upper, x,
                        tolerance, free)
    binding = False
    for j in range(free.size):
        binding = binding or free[j]
    vectors[ACTUATION, :] = proposed
    if apply_step:
        change = vectors[CHANGE]
        linearised = vectors[LINEARISED]
        for j in range(change.size):
            change[j] = proposed[j] - linearised[j]
        apply_linear_step_into(positions, rotations, solved[:, 0], solved[:, 1:], change,
                               max_rotation, increments, work)
        effector_points_into(positions, rotations, effector_frames, effector_offsets,
                             effector_positions)
    return SOLVED, iterations, largest_gap, largest_move, binding
