"""
The control tick as compiled code over one record of buffers (paper Sec. IV, `docs/design.md`).

:func:`control_tick` is one tick of :class:`cbha_inverse.core.inverse.solver.InverseSolver`, in
the order of the paper's section IV:

1. :func:`linearise_tick`, steps 1-2: the equilibrium's residual, ``J_aᵀ`` and symmetric
   tangent at the current state (:func:`~cbha_inverse.core._kernels.evaluation.evaluate`), the
   block Cholesky ``K = L Lᵀ`` with the forward sweep of ``[r, J_aᵀ]``, the sweep of ``J_eᵀ``,
   then :func:`project_tick`: ``W_ea``, ``W_aa``, ``δ_free`` (eq. 11-12), the equilibrium gap,
   the QP matrices and, with obstacles, the obstacle rows (:func:`obstacle_rows_of`); a call
   that also solves stops here when the gap exceeds ``gap_limit``;
2. :func:`solve_tick`, steps 3-4: the free gaps of the targets (:func:`free_gaps_of`, with the
   orientation targets of ``axis`` and ``pose`` effectors), the QP vectors, the active-set box QP
   (eq. 13; with obstacle rows, the active set over the rows around it, :func:`solve_qp_of`),
   its outcome, and the Newton step of the same factorization
   (:func:`apply_pending_step`: ``dq = K⁻¹ (r + J_aᵀ Δλ)``).

Its buffers and the model's constant arrays are one :class:`TickRecord` (fields
:data:`TICK_FIELDS`), held by :class:`cbha_inverse.core.inverse.tick_data.TickData`; Python
crosses into compiled code once per tick.
"""

import math

from cbha_inverse.core._kernels.block_band import (block_backward, block_cholesky_forward,
                                                   block_forward, first_nonzero_rows)
from cbha_inverse.core._kernels.evaluation import evaluate
from cbha_inverse.core._kernels.obstacle_rows import (add_entering_pairs, column_block_of,
                                                      row_outcome_of, rows_from_projection_of,
                                                      scale_rows_of, select_pairs_of,
                                                      targets_inside_obstacles)
from cbha_inverse.core._kernels.projection import (effector_columns_into, effector_jacobian_into,
                                                   effector_points_into, free_gaps_into,
                                                   orientation_errors_into,
                                                   project_effectors_into, target_status,
                                                   tick_outcome_into)
from cbha_inverse.core._kernels.qp import (active_set_box_qp_into, bounds_binding_into,
                                           qp_hessians_into, qp_vectors_into, rows_qp_into,
                                           SOLVED)
from cbha_inverse.core._kernels.records import define_record, Field, Record, RecordType
from cbha_inverse.core._kernels.retraction import apply_linear_step_into
import numba
from numba.experimental import structref
import numpy as np

F8, I8 = np.float64, np.int64

TICK_FIELDS = (
    Field('system', 'record', 0, 'the equilibrium evaluator (evaluation.EquilibriumRecord)'),
    Field('rows', 'record', 0, 'the obstacles, the collision spheres and the obstacle rows '
          '(obstacle_rows.ObstacleRowsRecord; no obstacle: none)'),
    # the state
    Field('positions', F8, 2, '(n + 1, 3) frame origins [m]'),
    Field('rotations', F8, 3, '(n + 1, 3, 3) frame rotations'),
    Field('actuation', F8, 1, '(m,) the actuation λ [Pa, N]'),
    Field('linearised', F8, 1, '(m,) λ_prev of the current linearisation'),
    # the actuators' constants
    Field('scale', F8, 1, '(m,) σ: λ = σ x'),
    Field('lower', F8, 1, '(m,) lower bounds [Pa, N]'),
    Field('upper', F8, 1, '(m,) upper bounds [Pa, N]'),
    Field('rate', F8, 1, '(m,) largest change per tick (inf: none) [Pa, N]'),
    # the effectors: 3k position rows, then o rotational rows (docs/effectors.md)
    Field('effector_frames', I8, 1, '(k,) frame of every effector point'),
    Field('effector_offsets', F8, 2, '(k, 3) effector points in their frame [m]'),
    Field('effector_kinds', I8, 1, '(k,) 0 point, 1 axis, 2 pose'),
    Field('effector_axes', F8, 2, '(k, 3) unit axis u of every axis effector, frame axes'),
    Field('orientation_effectors', I8, 1, '(o,) the effector of every rotational row'),
    Field('orientation_axes', F8, 2, '(o, 3) unit vector v of every rotational row, frame '
          'axes'),
    Field('row_weights', F8, 1, '(3k + o,) ω of every row [-, m/rad]'),
    Field('base', F8, 1, "(3,) base position, for the targets' check [m]"),
    Field('reach', F8, 1, '(k,) largest distance of each effector from the base [m]'),
    Field('target_directions', F8, 2, '(k, 3) unit target direction d of every axis effector'),
    Field('target_rotations', F8, 3, '(k, 3, 3) target rotation R_t of every pose effector'),
    # the linearisation (steps 1-2)
    Field('solved', F8, 2, '(6n, m + 1) L⁻¹ [r, J_aᵀ] (half_solved), or K⁻¹ [r, J_aᵀ]'),
    Field('column_starts', I8, 1, '(m + 1,) first nonzero row of each column of [r, J_aᵀ]'),
    Field('effector_columns', F8, 2, '(6n, 3k + o) L⁻¹ J_eᵀ (half_solved), or J_eᵀ'),
    Field('effector_starts', I8, 1, '(3k + o,) first nonzero row of each column of J_eᵀ'),
    Field('half_solved', np.bool_, 1, '(1,) whether solved and effector_columns are half-solves'),
    Field('levers', F8, 2, '(k, 3) effector levers R_f o [m]'),
    Field('orientation_directions', F8, 2, '(o, 3) world direction c = R_f v of every '
          'rotational row'),
    Field('moved', F8, 2, '(3k + o, m + 1) J_e K⁻¹ [r, J_aᵀ]'),
    Field('equilibrium_gap', F8, 1, '(1,) distance of the state from equilibrium [m] '
          '(equilibrium_gap_of)'),
    Field('gap_limit', F8, 1, '(1,) a tick that linearises and solves stops after the '
          'linearisation when equilibrium_gap exceeds it [m]'),
    Field('w_ea', F8, 2, '(3k + o, m) W_ea [m/Pa, m/N; rad/Pa, rad/N]'),
    Field('w_aa', F8, 2, '(m, m) W_aa'),
    Field('offset', F8, 1, '(3k + o,) p_e + J_e K⁻¹ r - W_ea λ_prev [m, rad]'),
    # the QP (step 3)
    Field('hessian', F8, 2, "(m, m) the QP's normalised Hessian"),
    Field('tracking', F8, 2, '(m, m) its tracking part'),
    Field('weighted_w', F8, 2, '(3k + o, m) Ω² W_ea σ / ν'),
    Field('tracking_norm', F8, 1, "(1,) ν, the tracking term's normaliser [m²]"),
    Field('energy_weight', float, 0, 'ε_E'),
    Field('proximal_weight', float, 0, 'ε_P'),
    Field('orientation_errors', F8, 2, '(k, 3) orientation error ψ of every effector [rad]'),
    Field('relative_rotation', F8, 2, '(3, 3) workspace: R_f R_tᵀ of a pose effector'),
    Field('delta_free', F8, 1, '(3k + o,) δ_free: offset - target, offset + c · ψ [m, rad]'),
    Field('gradient', F8, 1, "(m,) the QP's gradient"),
    Field('tracking_gradient', F8, 1, '(m,) its tracking part'),
    Field('box_lower', F8, 1, "(m,) the QP's box, lower"),
    Field('box_upper', F8, 1, "(m,) the QP's box, upper"),
    Field('x_previous', F8, 1, '(m,) λ_prev / σ'),
    Field('x', F8, 1, "(m,) the QP's solution"),
    Field('active_set', np.int8, 1, '(m,) -1 / 0 / +1: at the lower bound, free, at the upper'),
    Field('pivot', np.int8, 1, "(m,) the active set's pivots"),
    Field('free', np.bool_, 1, '(m,) free variables; after a solved QP, the binding bounds'),
    Field('qp_index', I8, 1, '(m,) workspace of the active set'),
    Field('qp_factor', F8, 2, '(m, m) factor of the free block'),
    Field('qp_solve', F8, 1, '(m,) its right-hand side'),
    Field('max_iterations', int, 0, 'active-set iteration limit'),
    Field('tolerance', float, 0, 'tolerance of the binding bounds'),
    # the outcome and the step (step 4)
    Field('proposed', F8, 1, '(m,) σ x within the bounds [Pa, N]'),
    Field('gap', F8, 1, '(3k + o,) W_ea λ + δ_free, the predicted effector gap [m, rad]'),
    Field('orientation_lengths', F8, 1, '(k,) orientation_length of every effector [m]'),
    Field('orientation_gap', F8, 1, '(2,) largest predicted orientation gap [rad], and times '
          'its orientation_length [m] (orientation_gap_of)'),
    Field('change', F8, 1, '(m,) λ - λ_prev of the step'),
    Field('increments', F8, 2, '(n, 6) the step [m, rad]'),
    Field('max_rotation', float, 0, 'largest frame rotation of a step [rad]'),
    Field('effector_positions', F8, 2, '(k, 3) effector positions after the tick [m]'),
)
"""The fields of :class:`TickRecord`."""


@structref.register
class TickRecordType(RecordType):
    """The numba type of :class:`TickRecord`."""


class TickRecord(Record):
    """The buffers of one solver's ticks (:data:`TICK_FIELDS`)."""

    __slots__ = ()


define_record(TickRecord, TickRecordType, TICK_FIELDS)


@numba.njit(cache=True)
def new_tick_record(*values):
    """Build a :class:`TickRecord` (fields in declaration order)."""
    return TickRecord(*values)


REJECTED = -1
"""The QP returned a non-finite actuation: the actuation and the state are unchanged."""
TARGET_NOT_FINITE = -2
"""Some target is not finite: nothing was done."""
BEYOND_REACH = -3
"""Some target is beyond reach (the caller clamps it): nothing was done."""
NOT_FACTORED = -4
"""The block Cholesky failed: nothing solved (the fallback chain of
:meth:`cbha_inverse.core.system.EquilibriumSystem.fallback_factors` takes over)."""
OFF_EQUILIBRIUM = -5
"""The linearised state's ``equilibrium_gap`` exceeds ``gap_limit``: linearised, nothing solved
(the caller checks the equilibrium before the QP)."""


@numba.njit(cache=True)
def control_tick(targets, tick, materialise, linearise, solve, apply_step):
    """
    Run one tick, or its parts: check the targets, linearise, solve the QP and step.

    Parameters
    ----------
    targets : (k, 3) ndarray  [m]
        Effector position targets (read only with ``solve``; the orientation targets are the
        record's ``target_directions`` and ``target_rotations``).
    tick : TickRecord
        The tick's buffers.
    materialise : bool
        Apply the kept linearisation's pending step to the frames first
        (:func:`apply_pending_step`).
    linearise : bool
        Linearise at the frames (:func:`linearise_tick`); else solve on the kept linearisation.
    solve : bool
        Check the targets and solve (:func:`solve_tick`); else stop after the linearisation.
    apply_step : bool
        Apply the Newton step after the QP (:func:`solve_tick`).

    Returns
    -------
    code : int
        :data:`TARGET_NOT_FINITE` or :data:`BEYOND_REACH` (nothing done), :data:`NOT_FACTORED`
        or :data:`OFF_EQUILIBRIUM` (nothing solved), else the code of :func:`solve_tick`
        (:data:`SOLVED` after a linearisation alone).
    iterations : int
        Active-set iterations (0 unless the QP ran).
    largest_gap : float  [m]
        Largest predicted effector gap (:func:`solve_tick`).
    largest_move : float
        Largest dimensionless actuation change (:func:`solve_tick`).
    binding : bool
        Whether some bound binds (:func:`solve_tick`).
    residual_norm : float  [N, N*m]
        ``|r|`` of the linearisation (NaN unless the tick linearised and factored).

    """
    nan = float('nan')
    if solve:
        checked = target_status(targets, tick.base, tick.reach)
        if checked == 1:
            return TARGET_NOT_FINITE, 0, nan, nan, False, nan
        if checked == 2:
            return BEYOND_REACH, 0, nan, nan, False, nan
    if materialise:
        apply_pending_step(tick)
    residual_norm = nan
    if linearise:
        info, residual_norm = linearise_tick(tick)
        if info != 0:
            return NOT_FACTORED, 0, nan, nan, False, nan
        if solve and not tick.equilibrium_gap[0] <= tick.gap_limit[0]:
            return OFF_EQUILIBRIUM, 0, nan, nan, False, residual_norm
    if not solve:
        return SOLVED, 0, nan, nan, False, residual_norm
    code, iterations, largest_gap, largest_move, binding = solve_tick(targets, tick, apply_step)
    return code, iterations, largest_gap, largest_move, binding, residual_norm


@numba.njit(cache=True)
def linearise_tick(tick):
    """
    Linearise, factor and project at the tick's state (steps 1-2), in place.

    :func:`~cbha_inverse.core._kernels.evaluation.evaluate` (the exact tangent's symmetric part
    into the block band), :func:`~cbha_inverse.core._kernels.block_band.block_cholesky_forward`
    (``K = L Lᵀ`` and, in the same pass, ``L⁻¹ [r, J_aᵀ]``), the forward sweep of ``J_eᵀ`` and
    :func:`project_tick`; each column's sweep starts at its first nonzero row (above it, the
    column and its sweep are zero). The backward sweep waits
    for the step (:func:`apply_pending_step`): one column, ``L⁻ᵀ (L⁻¹ r + L⁻¹ J_aᵀ Δλ)``.

    Parameters
    ----------
    tick : TickRecord
        The tick's buffers (reads the frames and ``actuation``; writes ``linearised``,
        ``solved``, ``effector_columns``, ``half_solved`` and the projection).

    Returns
    -------
    info : int
        0 if the block Cholesky succeeded (everything written), else nonzero.
    residual_norm : float  [N, N*m]
        ``|r|`` (NaN unless ``info`` is 0).

    """
    system, solved = tick.system, tick.solved
    evaluate(system, tick.positions, tick.rotations, tick.actuation, bool(True), bool(True))
    linearised, actuation = tick.linearised, tick.actuation
    for j in range(actuation.size):
        linearised[j] = actuation[j]
    tick.half_solved[0] = False
    rhs = system.rhs
    for row in range(rhs.shape[0]):
        for col in range(rhs.shape[1]):
            solved[row, col] = rhs[row, col]
    first_nonzero_rows(solved, tick.column_starts)
    factor = system.blocks[:solved.shape[0] // 6]
    info = block_cholesky_forward(factor, solved, tick.column_starts)
    if info != 0:
        return info, float('nan')
    effector_jacobian_of(tick)
    first_nonzero_rows(tick.effector_columns, tick.effector_starts)
    block_forward(factor, tick.effector_columns, tick.effector_starts)
    tick.half_solved[0] = True
    return 0, project_tick(tick)


@numba.njit(cache=True)
def project_tick(tick):
    """
    Project a solved linearisation and form the QP matrices (the end of step 2), in place.

    :func:`~cbha_inverse.core._kernels.projection.project_effectors_into`, the state's
    distance from equilibrium (:func:`equilibrium_gap_of`), then
    :func:`~cbha_inverse.core._kernels.qp.qp_hessians_into`: ``w_ea``, ``w_aa``, ``offset``,
    ``equilibrium_gap``, ``hessian``, ``tracking`` and ``weighted_w``. Without ``half_solved``
    (``solved`` holds ``K⁻¹ [r, J_aᵀ]`` of another factor: the fallback chain) it first writes
    ``J_eᵀ`` into ``effector_columns``.

    Returns
    -------
    float  [N, N*m]
        ``|r|``.

    """
    half = tick.half_solved[0]
    if not half:
        effector_jacobian_of(tick)
    residual_norm = project_effectors_into(
        tick.solved, tick.system.rhs, tick.effector_columns, half, tick.column_starts,
        tick.positions, tick.rotations, tick.effector_frames, tick.effector_offsets,
        tick.orientation_effectors, tick.linearised, tick.w_ea, tick.w_aa, tick.offset,
        tick.moved)
    position_rows = 3 * tick.effector_frames.size
    tick.equilibrium_gap[0] = equilibrium_gap_of(tick.moved[:position_rows])
    tick.tracking_norm[0] = qp_hessians_into(
        tick.w_ea, tick.w_aa, tick.scale, tick.energy_weight, tick.proximal_weight,
        tick.row_weights, tick.hessian, tick.tracking, tick.weighted_w)
    if tick.rows.obstacle_shapes.size:
        obstacle_rows_of(tick)
    return residual_norm


@numba.njit(cache=True)
def obstacle_rows_of(tick):
    """
    Write the obstacle rows of the tick's linearisation into its ``rows``; return their count.

    The pairs within reach at the linearisation's frames
    (:func:`~cbha_inverse.core._kernels.obstacle_rows.select_pairs_of`), the projection of
    their spheres' centres (:func:`project_points_of`) and the rows' ``G``, ``c``
    (:func:`~cbha_inverse.core._kernels.obstacle_rows.rows_from_projection_of`,
    ``docs/obstacles.md``).
    """
    rows = tick.rows
    count = select_pairs_of(rows, tick.positions)
    if count:
        points = 3 * count
        project_points_of(tick, rows.row_frames[:count], rows.offsets[:count],
                          rows.levers[:count], column_block_of(rows, tick.solved.shape[0]),
                          rows.starts[:points], rows.w_pa[:points], rows.w_aa,
                          rows.free_centres[:points], rows.moved[:points])
        rows_from_projection_of(rows, tick.positions)
    return count


@numba.njit(cache=True)
def project_points_of(tick, frames, offsets, levers, columns, starts, w_pa, w_aa, offset,
                      moved):
    """
    Project points on the frames (the collision spheres' centres) as effector points, in place.

    The rows of ``W_pa = J_p K⁻¹ J_aᵀ`` and the free points ``p + J_p K⁻¹ r - W_pa λ_prev`` of
    the tick's linearisation (eq. 11 for these points, ``docs/obstacles.md``): ``J_pᵀ`` by
    :func:`~cbha_inverse.core._kernels.projection.effector_columns_into`, its forward sweep by
    the block factor when ``solved`` holds half-solves, then
    :func:`~cbha_inverse.core._kernels.projection.project_effectors_into`, as for the effectors.

    Parameters
    ----------
    tick : TickRecord
        A linearisation (:func:`linearise_tick` or the fallback chain's ``project_tick``).
    frames : (s,) int ndarray
        Frame of every point (1..n).
    offsets : (s, 3) ndarray  [m]
        The points in their frame's axes.
    levers : (s, 3) ndarray  [m]
        Workspace: ``R_f o``.
    columns : (6n, 3s) ndarray
        Workspace: ``J_pᵀ``, then ``L⁻¹ J_pᵀ``.
    starts : (3s,) int ndarray
        Workspace: the first nonzero row of each column.
    w_pa : (3s, m) ndarray  [m/Pa, m/N]
        Receives ``W_pa``.
    w_aa : (m, m) ndarray
        Workspace (``W_aa`` again).
    offset : (3s,) ndarray  [m]
        Receives ``p + J_p K⁻¹ r - W_pa λ_prev``: the points' linear model is
        ``offset + W_pa λ``.
    moved : (3s, m + 1) ndarray
        Workspace: ``J_p K⁻¹ [r, J_aᵀ]``.

    """
    half = tick.half_solved[0]
    effector_columns_into(tick.rotations, frames, offsets, levers, columns)
    if half:
        first_nonzero_rows(columns, starts)
        block_forward(tick.system.blocks[:tick.solved.shape[0] // 6], columns, starts)
    # 3s rows, all position rows: the rotational rows' effectors are not read
    project_effectors_into(tick.solved, tick.system.rhs, columns, half, tick.column_starts,
                           tick.positions, tick.rotations, frames, offsets,
                           tick.orientation_effectors, tick.linearised, w_pa, w_aa, offset,
                           moved)


@numba.njit(cache=True)
def effector_jacobian_of(tick):
    """
    Write ``J_eᵀ`` at the tick's frames into ``effector_columns``.

    :func:`~cbha_inverse.core._kernels.projection.effector_jacobian_into`, with ``levers`` and
    the rotational rows' ``orientation_directions``.
    """
    effector_jacobian_into(tick.rotations, tick.effector_frames, tick.effector_offsets,
                           tick.orientation_effectors, tick.orientation_axes, tick.levers,
                           tick.orientation_directions, tick.effector_columns)


@numba.njit(cache=True)
def equilibrium_gap_of(moved):
    """
    Return the largest effector move of a Newton step at the current actuation [m].

    ``max_e |(J_e K⁻¹ r)_e|``, column 0 of ``moved`` (three rows per effector): to first order,
    each effector's distance from the model's equilibrium at the actuation of the
    linearisation. Infinite when a move is not finite.

    Parameters
    ----------
    moved : (3k, m + 1) ndarray  [m, m/Pa or m/N]
        The position rows of ``J_e K⁻¹ [r, J_aᵀ]``.

    Returns
    -------
    float  [m]

    """
    largest = 0.0
    for row in range(0, moved.shape[0], 3):
        move = math.sqrt(moved[row, 0] ** 2 + moved[row + 1, 0] ** 2 + moved[row + 2, 0] ** 2)
        if not math.isfinite(move):
            return math.inf
        largest = max(largest, move)
    return largest


@numba.njit(cache=True)
def solve_tick(targets, tick, apply_step):
    """
    Solve a tick's QP on a linearisation and apply it (steps 3-4 of the tick), in place.

    ``δ_free`` (:func:`free_gaps_of`), the QP vectors
    (:func:`~cbha_inverse.core._kernels.qp.qp_vectors_into`), the QP (:func:`solve_qp_of`: the
    active-set box QP, warm-started from ``active_set``, with the obstacle rows when there are
    some), the outcome (:func:`~cbha_inverse.core._kernels.projection.tick_outcome_into`), the
    check of a long step for spheres entering obstacles without a row (:func:`add_entering_rows`:
    a step moving an actuator by more than the rows' ``entering_move`` adds their rows and
    solves again, ``entering_rounds`` solves at most), the rows' outcome
    (:func:`~cbha_inverse.core._kernels.obstacle_rows.row_outcome_of`) and the binding bounds
    (:func:`~cbha_inverse.core._kernels.qp.bounds_binding_into`). With ``apply_step`` the
    Newton step of the factorization (:func:`apply_pending_step`) moves the frames and the
    effector positions of the new state are written; without it, those the linear model
    predicts (the targets plus the predicted gaps, paper eq. 11).

    Parameters
    ----------
    targets : (k, 3) ndarray  [m]
        Finite effector targets within reach.
    tick : TickRecord
        The tick's buffers as :func:`linearise_tick` left them.
    apply_step : bool
        Apply the linear step now (``relinearize_every`` 1).

    Returns
    -------
    code : int
        :data:`~cbha_inverse.core._kernels.qp.SOLVED`, the active set's failure code
        (``MAX_ITERATIONS``, ``SINGULAR``, ``ROWS_UNSETTLED``: the QP vectors are written, and
        the rows, nothing else) or :data:`REJECTED`.
    iterations : int
        Active-set iterations (of all solves).
    largest_gap : float  [m]
        Largest predicted effector gap.
    largest_move : float
        Largest dimensionless actuation change.
    binding : bool
        Whether some bound binds (the QP is solved and the tick saturated).

    """
    k = targets.shape[0]
    delta_free, gap = tick.delta_free, tick.gap
    free_gaps_of(targets, tick)
    qp_vectors_into(tick.weighted_w, tick.proximal_weight, tick.scale, delta_free,
                    tick.actuation, tick.lower, tick.upper, tick.rate, tick.gradient,
                    tick.box_lower, tick.box_upper, tick.x_previous, tick.tracking_gradient)
    rows = tick.rows
    iterations = 0
    for _ in range(max(rows.entering_rounds, 1)):
        code, done = solve_qp_of(tick)
        iterations += done
        if code != SOLVED:
            return code, iterations, 0.0, 0.0, False
        largest_gap, largest_move, finite = tick_outcome_into(
            tick.w_ea, delta_free, tick.scale, tick.x, tick.x_previous, tick.lower, tick.upper,
            3 * k, tick.proposed, gap)
        if not finite:
            return REJECTED, iterations, largest_gap, largest_move, False
        if (not rows.obstacle_shapes.size or largest_move <= rows.entering_move
                or not add_entering_rows(tick, tick.proposed)):
            break
    row_outcome_of(rows, tick.x, tick.proposed)
    if tick.orientation_effectors.size:
        orientation_gap_of(tick)
    bounds_binding_into(tick.tracking, tick.tracking_gradient, tick.box_lower, tick.box_upper,
                        tick.x, tick.tolerance, tick.free)
    binding = False
    for j in range(tick.free.size):
        binding = binding or tick.free[j]
    actuation, proposed = tick.actuation, tick.proposed
    for j in range(actuation.size):
        actuation[j] = proposed[j]
    effector_positions = tick.effector_positions
    if apply_step:
        apply_pending_step(tick)
        effector_points_into(tick.positions, tick.rotations, tick.effector_frames,
                             tick.effector_offsets, effector_positions)
    else:
        for e in range(k):
            for i in range(3):
                effector_positions[e, i] = targets[e, i] + gap[3 * e + i]
    return SOLVED, iterations, largest_gap, largest_move, binding


@numba.njit(cache=True)
def solve_qp_of(tick):
    """
    Solve the tick's QP into ``x``: the box QP, or with the obstacle rows the rows QP.

    Without rows, :func:`~cbha_inverse.core._kernels.qp.active_set_box_qp_into`; with ``r``
    rows, :func:`~cbha_inverse.core._kernels.qp.rows_qp_into` on ``A = G σ``, ``b = c`` and
    the penalty ``ρ / ν`` of their slack (``docs/obstacles.md``), each row's state started from
    its sign at ``x_prev`` (:func:`~cbha_inverse.core._kernels.obstacle_rows.scale_rows_of`),
    ``4 r + 10`` box QPs at most. Both warm-start from ``active_set``.

    Returns
    -------
    code : int
        :data:`~cbha_inverse.core._kernels.qp.SOLVED` or the solver's failure code.
    iterations : int
        Active-set iterations.

    """
    rows = tick.rows
    count = rows.count[0]
    if not count:
        return active_set_box_qp_into(
            tick.hessian, tick.gradient, tick.box_lower, tick.box_upper, tick.active_set,
            tick.max_iterations, tick.x, tick.free, tick.pivot, tick.qp_index, tick.qp_factor,
            tick.qp_solve)
    scale_rows_of(rows, tick.scale, tick.x_previous)
    code, iterations, _ = rows_qp_into(
        tick.hessian, tick.gradient, tick.box_lower, tick.box_upper, rows.scaled_matrix[:count],
        rows.constant[:count], rows.weight / tick.tracking_norm[0], tick.active_set,
        rows.row_on[:count], tick.max_iterations, 4 * count + 10, tick.x, tick.free, tick.pivot,
        tick.qp_index, tick.qp_factor, tick.qp_solve, rows.penalised_hessian,
        rows.penalised_gradient, rows.values[:count])
    return code, iterations


@numba.njit(cache=True)
def add_entering_rows(tick, actuation):
    """
    Add the rows of the pairs the step to ``actuation`` carries within the margin; relinearise.

    The step of the linearisation to ``actuation`` (m,) [Pa, N] on copies of the frames
    (:func:`step_to_into` into the rows' ``stepped_positions`` and ``stepped_rotations``), the
    pairs without a row it brings within ``margin``
    (:func:`~cbha_inverse.core._kernels.obstacle_rows.add_entering_pairs`) and, when it added
    one, the rows again at the same linearisation (:func:`obstacle_rows_of`): the caller solves
    again. Returns whether a pair was added.
    """
    rows = tick.rows
    positions, rotations = rows.stepped_positions, rows.stepped_rotations
    for f in range(positions.shape[0]):
        for i in range(3):
            positions[f, i] = tick.positions[f, i]
            for j in range(3):
                rotations[f, i, j] = tick.rotations[f, i, j]
    step_to_into(tick, actuation, positions, rotations)
    if not add_entering_pairs(rows, positions):
        return False
    obstacle_rows_of(tick)
    return True


@numba.njit(cache=True)
def targets_inside_of(targets, tick):
    """
    Mark the obstacles some target lies inside of in ``rows.targets_inside``; return the count.

    :func:`~cbha_inverse.core._kernels.obstacle_rows.targets_inside_obstacles` over the tick's
    obstacles, ``targets`` (k, 3) [m].
    """
    return targets_inside_obstacles(tick.rows, targets)


@numba.njit(cache=True)
def free_gaps_of(targets, tick):
    """
    Write ``δ_free`` of the targets on the tick's linearisation into ``delta_free`` (eq. 11).

    The orientation errors ``ψ`` of the ``axis`` and ``pose`` effectors at the linearisation's
    frames to their targets (``target_directions``, ``target_rotations``), when the effectors
    have rotational rows, then
    :func:`~cbha_inverse.core._kernels.projection.free_gaps_into`: ``offset - target`` on the
    position rows, ``offset + c · ψ`` on the rotational rows.

    Parameters
    ----------
    targets : (k, 3) ndarray  [m]
        Effector position targets.
    tick : TickRecord
        The tick's buffers (a linearisation).

    """
    if tick.orientation_effectors.size:
        orientation_errors_into(tick.rotations, tick.effector_frames, tick.effector_kinds,
                                tick.effector_axes, tick.target_rotations,
                                tick.target_directions, tick.orientation_errors,
                                tick.relative_rotation)
    free_gaps_into(tick.offset, targets, tick.orientation_effectors, tick.orientation_directions,
                   tick.orientation_errors, tick.delta_free)


@numba.njit(cache=True)
def orientation_gap_of(tick):
    """
    Write the largest predicted orientation gap of the tick into ``orientation_gap``.

    Each ``axis`` or ``pose`` effector's gap is the norm of its rotational rows of ``gap``
    (``W_ea λ + δ_free``) [rad]; ``orientation_gap`` receives the largest, and the largest
    times its effector's ``orientation_length`` [m].
    """
    gap, rows = tick.gap, tick.orientation_effectors
    first = 3 * tick.effector_frames.size
    largest = largest_length = 0.0
    start = 0
    while start < rows.size:
        end, squares = start, 0.0
        while end < rows.size and rows[end] == rows[start]:
            squares += gap[first + end] ** 2
            end += 1
        turn = math.sqrt(squares)
        largest = max(largest, turn)
        largest_length = max(largest_length, turn * tick.orientation_lengths[rows[start]])
        start = end
    tick.orientation_gap[0] = largest
    tick.orientation_gap[1] = largest_length


@numba.njit(cache=True)
def apply_pending_step(tick):
    """Apply the Newton step of the linearisation to the tick's frames, in place."""
    pending_step_into(tick, tick.positions, tick.rotations)


@numba.njit(cache=True)
def pending_step_into(tick, positions, rotations):
    """
    Apply the Newton step of the tick's linearisation to given frames, in place.

    The step to the tick's ``actuation`` (:func:`step_to_into`).

    Parameters
    ----------
    tick : TickRecord
        The tick's buffers (a solved linearisation).
    positions : (n + 1, 3) ndarray  [m]
        Frame origins (updated; the tick's or a copy).
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations (updated).

    """
    step_to_into(tick, tick.actuation, positions, rotations)


@numba.njit(cache=True)
def step_to_into(tick, actuation, positions, rotations):
    """
    Apply the Newton step of the tick's linearisation to an actuation to given frames, in place.

    ``dq = K⁻¹ r + K⁻¹ J_aᵀ (λ - λ_prev)`` (``change`` receives ``λ - λ_prev``), by
    :func:`~cbha_inverse.core._kernels.retraction.apply_linear_step_into` on ``solved``: with
    ``half_solved`` the half-solves, then one backward sweep of the block factor.

    Parameters
    ----------
    tick : TickRecord
        The tick's buffers (a solved linearisation).
    actuation : (m,) ndarray  [Pa, N]
        ``λ``.
    positions : (n + 1, 3) ndarray  [m]
        Frame origins (updated).
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations (updated).

    """
    change, solved, system = tick.change, tick.solved, tick.system
    for j in range(change.size):
        change[j] = actuation[j] - tick.linearised[j]
    apply_linear_step_into(positions, rotations, solved[:, 0], solved[:, 1:], change,
                           tick.max_rotation, tick.increments,
                           system.blocks[:solved.shape[0] // 6], tick.half_solved[0])


@numba.njit(cache=True)
def attach_rows(tick, rows):
    """Make ``rows`` (an ``ObstacleRowsRecord``) the tick's obstacle rows."""
    tick.rows = rows


@numba.njit(cache=True)
def backward_solves(tick):
    """
    Complete the half-solves of a linearisation, ``solved <- K⁻¹ [r, J_aᵀ]``, in place.

    One backward sweep of the block factor (the shape estimator's full solves); nothing to do
    when ``solved`` already holds full solves.
    """
    if tick.half_solved[0]:
        block_backward(tick.system.blocks[:tick.solved.shape[0] // 6], tick.solved)
        tick.half_solved[0] = False
