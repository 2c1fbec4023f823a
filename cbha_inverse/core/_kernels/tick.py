"""
The control tick as compiled entry points over preallocated buffers (`docs/design.md`).

:func:`linearise_tick` is steps 1-2 of :class:`cbha_inverse.core.inverse.solver.InverseSolver`
(links and cables, band assembly, band Cholesky, the forward sweeps of ``[r, J_aᵀ]`` and
``J_eᵀ``, the projection onto the effectors and actuators and the QP matrices);
:func:`solve_tick` is steps 3-4 (the QP vectors from the targets, the active-set box QP, the
outcome, the binding bounds, the linear step with its backward sweep and the effector
positions). :func:`control_tick` runs a whole tick of the active set in one call: the targets'
check, :func:`linearise_tick` (when the tick linearises) and :func:`solve_tick`. Each calls the
kernels of this folder that hold the equations (numba
compiles them into the entry): nothing here is a second copy of their arithmetic. Python crosses
into compiled code once per step instead of once per kernel, and no array is allocated: the
buffers are those of :class:`cbha_inverse.core.inverse.tick_data.TickData`, grouped by shape
into a few stacked arrays, held by one
:class:`~cbha_inverse.core._kernels.tick_buffers.TickBuffers`: an entry takes it as one argument
(numba unboxes every argument at every call). The small kernels an entry calls once carry
numba's ``inline='always'`` (the QP's vectors, Hessians and binding bounds, the outcome, the
targets' check, the effector points and columns, the projection, the Newton step): a compiled
callee that is not inlined costs its caller a pair of reference-count calls for every array
view it is handed (352 such calls per CBHA tick remain, 430 before; `docs/design.md`). The
rows of the stacks are the constants below.
"""

from cbha_inverse.core._kernels.band import band_cholesky_forward, band_forward_profiled
from cbha_inverse.core._kernels.band_assembly import band_rows, scatter_add, scatter_more
from cbha_inverse.core._kernels.cables import cable_pass_into
from cbha_inverse.core._kernels.links import link_pass_band_into, link_pass_into
from cbha_inverse.core._kernels.projection import (effector_columns_into, effector_points_into,
                                                   project_effectors_into, target_status,
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
# codes of control_tick beside solve_tick's: it returned before the QP
TARGET_NOT_FINITE = -2
"""Some target is not finite: nothing was done."""
BEYOND_REACH = -3
"""Some target is beyond reach (the caller clamps it): nothing was done."""
NOT_FACTORED = -4
"""The band Cholesky failed (or was not asked for): the evaluation is written, for the fallback
chain (:meth:`cbha_inverse.core.system.EquilibriumSystem.fallback_factors`)."""


def compiled_entry(dispatcher, *arguments):
    """
    Return the compiled wrapper of an entry for the types of the given arguments.

    Compiles the entry for them, or loads it from numba's on-disk cache. Calling the wrapper
    skips numba's type dispatch, which types a :class:`TickBuffers
    <cbha_inverse.core._kernels.tick_buffers.TickBuffers>` on its slow path at every call (a
    few tenths of a microsecond per call, the argument's unboxing aside); the caller passes
    arguments of exactly these types (the wrapper does not check them).

    Parameters
    ----------
    dispatcher : numba dispatcher
        :func:`control_tick`, :func:`linearise_tick`, :func:`solve_tick`,
        :func:`apply_pending_step`, :func:`pending_step_into` or :func:`project_tick`.
    *arguments
        Example arguments (their numba types are the signature).

    Returns
    -------
    callable
        The entry itself with numba's JIT off (``NUMBA_DISABLE_JIT=1``).

    """
    if numba.config.DISABLE_JIT:
        return dispatcher
    signature = tuple(numba.typeof(argument) for argument in arguments)
    dispatcher.compile(signature)
    return dispatcher.get_overload(signature)


@numba.njit(cache=True)
def control_tick(targets, buffers, materialise, linearise, cholesky, apply_step):
    """
    Run one tick of the active set: check the targets, linearise if asked, solve and step.

    :func:`~cbha_inverse.core._kernels.projection.target_status` on ``buffers.base`` and
    ``buffers.reach``; when the targets are finite and within reach, :func:`apply_pending_step`
    (``materialise``), :func:`linearise_tick` (``linearise``) and, when it factored the band
    (or the tick keeps a linearisation), :func:`solve_tick`. The calls of the three entries one
    by one, in one crossing into compiled code: the same arithmetic, the same results.

    Parameters
    ----------
    targets : (k, 3) ndarray  [m]
        Effector targets.
    buffers : cbha_inverse.core._kernels.tick_buffers.TickBuffers
        The tick's buffers (as :func:`linearise_tick` and :func:`solve_tick` read and write
        them).
    materialise : bool
        Apply the kept linearisation's pending step to the frames before linearising.
    linearise : bool
        Linearise at the frames (else solve on the kept linearisation).
    cholesky : bool
        Factor the band (:func:`linearise_tick`).
    apply_step : bool
        Apply the linear step after the QP (:func:`solve_tick`).

    Returns
    -------
    code : int
        :data:`TARGET_NOT_FINITE` or :data:`BEYOND_REACH` (nothing done), :data:`NOT_FACTORED`
        (the pending step applied if asked, the evaluation written, nothing solved), else the
        code of :func:`solve_tick`.
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
    checked = target_status(targets, buffers.base, buffers.reach)
    if checked == 1:
        return TARGET_NOT_FINITE, 0, nan, nan, False, nan
    if checked == 2:
        return BEYOND_REACH, 0, nan, nan, False, nan
    if materialise:
        apply_pending_step(buffers)
    residual_norm = nan
    if linearise:
        info, residual_norm = linearise_tick(buffers, cholesky)
        if info != 0:
            return NOT_FACTORED, 0, nan, nan, False, nan
    code, iterations, largest_gap, largest_move, binding = solve_tick(targets, buffers,
                                                                      apply_step)
    return code, iterations, largest_gap, largest_move, binding, residual_norm


@numba.njit(cache=True)
def linearise_tick(buffers, cholesky):
    """
    Linearise, factor and project at the buffers' state (steps 1-2 of the tick), in place.

    Runs :func:`~cbha_inverse.core._kernels.links.link_pass_band_into` (the links' symmetric
    tangent straight into the symmetric lower band),
    :func:`~cbha_inverse.core._kernels.cables.cable_pass_into` (one cable group, or none; its
    blocks scattered into the band,
    :func:`~cbha_inverse.core._kernels.band_assembly.scatter_more`),
    :func:`~cbha_inverse.core._kernels.band.band_cholesky_forward` (``K = L Lᵀ`` and, in the same
    pass, the forward sweep ``L⁻¹ [r, J_aᵀ]``) and, when it succeeds, the forward sweep
    (:func:`~cbha_inverse.core._kernels.band.band_forward`) ``L⁻¹ J_eᵀ`` (from the effector
    frame's rows on: ``J_eᵀ`` is zero above them) and :func:`project_tick`. The backward
    sweep waits for the step (:func:`apply_pending_step`): one column,
    ``L⁻ᵀ (L⁻¹ r + L⁻¹ J_aᵀ Δλ)``.

    Parameters
    ----------
    buffers : cbha_inverse.core._kernels.tick_buffers.TickBuffers
        The tick's buffers. Reads the frames, ``vectors[ACTUATION]`` (``λ_prev``) and
        ``vectors[SCALE]``, the evaluation's terms, ``external`` and the effectors; writes
        ``band`` (the symmetric lower band, last row: the base frame's trash, then its factor),
        ``rhs`` (``[r, J_aᵀ]``), ``values`` (the cable blocks; the link blocks too when
        ``cholesky`` is False or the Cholesky fails: the exact evaluation, run again then),
        ``vectors[LINEARISED]``, ``solved`` (``L⁻¹ [r, J_aᵀ]``; partly swept when the Cholesky
        fails) and, when the Cholesky succeeds, ``effector_columns`` (``L⁻¹ J_eᵀ``),
        ``half_solved`` (True), ``profiled`` and the projection (:func:`project_tick`).
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
    vectors, rhs = buffers.vectors, buffers.rhs
    _evaluate(buffers, cholesky)
    factor = band_rows(buffers.band, rhs.shape[0])
    vectors[LINEARISED, :] = vectors[ACTUATION]
    buffers.half_solved[0] = False
    if not cholesky:
        return -1, float('nan')
    solved, columns, rotations = buffers.solved, buffers.effector_columns, buffers.rotations
    # over the flat storage (both C order, one shape): numba's 2-D slice assignment indexes and
    # broadcasts element by element (~0.35 µs more on the CBHA's 96 x 7)
    flat_solved, flat_rhs = solved.reshape(solved.size), rhs.reshape(rhs.size)
    for i in range(flat_rhs.size):
        flat_solved[i] = flat_rhs[i]
    # the block profile checked once, by the Cholesky on the band: its factor keeps it; the
    # forward sweep of [r, J_aᵀ] in the same pass over the factor
    info, profiled = band_cholesky_forward(factor, solved)
    if info != 0:
        # the symmetric pass left the link blocks of ``values`` unwritten: the exact evaluation
        # again, for the fallback chain (only when the Cholesky fails)
        _evaluate(buffers, False)
        return info, float('nan')
    first = effector_columns_into(rotations, buffers.effector_frames, buffers.effector_offsets,
                                  buffers.levers, columns)
    band_forward_profiled(factor, columns, first, profiled)
    buffers.half_solved[0] = True
    # for the backward sweep of the step (stored here, after the sweeps: stored right after
    # the Cholesky, it made the linearisation 0.4 µs slower, LLVM's doing)
    buffers.profiled[0] = profiled
    return 0, project_tick(buffers)


@numba.njit(cache=True)
def _evaluate(buffers, symmetric):
    """
    Evaluate the links, the cable group and the external wrenches into the tick's buffers.

    ``rhs`` receives ``[r, J_aᵀ]``; ``band`` the symmetric lower band (its trash row aside).
    With ``symmetric`` the links add the symmetric part of their tangents straight into the
    band (:func:`~cbha_inverse.core._kernels.links.link_pass_band_into`; their blocks in
    ``values`` are not written) and only the cable values are scattered; else ``values``
    receives every exact block and the band is their scatter
    (:func:`~cbha_inverse.core._kernels.band_assembly.scatter_add`, what the fallback chain reads).
    """
    positions, rotations, actuation = buffers.positions, buffers.rotations, buffers.vectors[
        ACTUATION]
    stiffness, counts, values = buffers.stiffness, buffers.counts, buffers.values
    rhs, band, external = buffers.rhs, buffers.band, buffers.external
    cable_frames, cable_spans = buffers.cable_frames, buffers.cable_spans
    cable_points = buffers.cable_points
    n = stiffness.shape[0]
    link_end = counts[0]
    pair_end = link_end + counts[1]
    moment_end = pair_end + counts[2]
    if symmetric:
        band[:] = 0.0
        link_pass_band_into(positions, rotations, stiffness, buffers.rest_offsets,
                            buffers.rest_rotations_t, actuation, buffers.cavity_wrench,
                            buffers.cavity_stiffness, buffers.cavity_columns, rhs, band,
                            buffers.link_work)
    else:
        link_pass_into(positions, rotations, stiffness, buffers.rest_offsets,
                       buffers.rest_rotations_t, actuation, buffers.cavity_wrench,
                       buffers.cavity_stiffness, buffers.cavity_columns, rhs,
                       values[:link_end].reshape((n, 12, 12)), False, buffers.link_work)
    if cable_frames.size > 0:
        cable_pass_into(positions, rotations, actuation, buffers.cable_gains, cable_frames,
                        buffers.cable_offsets, cable_spans[0], cable_spans[1], cable_spans[2],
                        cable_points[0], buffers.cable_columns, cable_spans[3], cable_points[1],
                        rhs, values[link_end:pair_end].reshape((-1, 12, 12)),
                        values[pair_end:moment_end].reshape((-1, 3, 3)), buffers.cable_work)
    for row in range(rhs.shape[0]):
        rhs[row, 0] += external[row]
    if symmetric:
        scatter_more(buffers.index, values, buffers.slot_weights, band, link_end)
    else:
        scatter_add(buffers.index, values, buffers.slot_weights, band)


@numba.njit(cache=True)
def project_tick(buffers):
    """
    Project a solved linearisation and form the QP matrices (the end of step 2), in place.

    :func:`~cbha_inverse.core._kernels.projection.project_effectors_into` then
    :func:`~cbha_inverse.core._kernels.qp.qp_hessians_into` on the buffers
    (:class:`~cbha_inverse.core._kernels.tick_buffers.TickBuffers`; ``solved``, ``rhs``,
    ``effector_columns``, ``half_solved`` and ``vectors[LINEARISED]`` = ``λ_prev`` are read);
    writes ``W_EA``, ``WEIGHTED_W``, ``W_AA``, ``HESSIAN``, ``TRACKING`` and ``OFFSET``. Without
    ``half_solved`` (``solved`` holds ``K⁻¹ [r, J_aᵀ]`` of another factor: the fallback
    chain) it first writes ``J_eᵀ`` into ``effector_columns``.

    Returns
    -------
    float  [N, N*m]
        ``|r|``.

    """
    vectors, matrices = buffers.vectors, buffers.matrices
    effector_matrices, weights = buffers.effector_matrices, buffers.weights
    w_ea = effector_matrices[W_EA]
    w_aa = matrices[W_AA]
    half = buffers.half_solved[0]
    if not half:
        effector_columns_into(buffers.rotations, buffers.effector_frames,
                              buffers.effector_offsets, buffers.levers, buffers.effector_columns)
    residual_norm = project_effectors_into(
        buffers.solved, buffers.rhs, buffers.effector_columns, half, buffers.positions,
        buffers.rotations, buffers.effector_frames, buffers.effector_offsets, vectors[LINEARISED],
        w_ea, w_aa, buffers.gaps[OFFSET], buffers.moved)
    qp_hessians_into(w_ea, w_aa, vectors[SCALE], weights[0], weights[1], matrices[HESSIAN],
                     matrices[TRACKING], effector_matrices[WEIGHTED_W])
    return residual_norm


@numba.njit(cache=True)
def solve_tick(targets, buffers, apply_step):
    """
    Solve a tick's QP on a linearisation and apply it (steps 3-4 of the tick), in place.

    Forms ``δ_free`` (the targets are checked by the caller,
    :func:`~cbha_inverse.core._kernels.projection.target_status`) and the QP vectors
    (:func:`~cbha_inverse.core._kernels.qp.qp_vectors_into`), solves the box QP by the active
    set (:func:`~cbha_inverse.core._kernels.qp.active_set_box_qp_into`, warm-started from
    ``flags[STATE]``), then the outcome
    (:func:`~cbha_inverse.core._kernels.projection.tick_outcome_into`) and the binding bounds
    (:func:`~cbha_inverse.core._kernels.qp.bounds_binding_into`). With ``apply_step`` the
    Newton step of the factorization (:func:`apply_pending_step`) moves the frames and the
    effector positions of the new state are written; without it, those the linear model
    predicts (the targets plus the predicted gaps).

    Parameters
    ----------
    targets : (k, 3) ndarray  [m]
        Finite effector targets within reach.
    buffers : cbha_inverse.core._kernels.tick_buffers.TickBuffers
        The tick's buffers as :func:`linearise_tick` left them. Writes ``DELTA_FREE``, the QP
        vectors, ``X``, ``PROPOSED``, ``GAP``, ``STATE``, ``free`` (on return the binding
        bounds, ``saturated``, when the QP is solved) and, unless the code is
        :data:`REJECTED` or the QP failed, ``ACTUATION`` and ``effector_positions``; with
        ``apply_step`` the frames.
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
    vectors, matrices, gaps = buffers.vectors, buffers.matrices, buffers.gaps
    effector_matrices, flags, free = buffers.effector_matrices, buffers.flags, buffers.free
    k = targets.shape[0]
    offset, delta_free, gap = gaps[OFFSET], gaps[DELTA_FREE], gaps[GAP]
    for e in range(k):
        for i in range(3):
            delta_free[3 * e + i] = offset[3 * e + i] - targets[e, i]
    weighted_w = effector_matrices[WEIGHTED_W]
    rate = vectors[RATE]
    qp_vectors_into(weighted_w, buffers.weights[1], vectors[SCALE], delta_free,
                    vectors[ACTUATION], vectors[LOWER], vectors[UPPER], rate, vectors[GRADIENT:])
    hessian = matrices[HESSIAN]
    lower, upper = vectors[BOX_LOWER], vectors[BOX_UPPER]
    x = vectors[X]
    code, iterations = active_set_box_qp_into(
        hessian, vectors[GRADIENT], lower, upper, flags[STATE], buffers.max_iterations, x, free,
        flags[PIVOT], buffers.qp_index, matrices[FACTOR], vectors[SOLVE])
    if code != SOLVED:
        return code, iterations, 0.0, 0.0, False
    proposed = vectors[PROPOSED]
    largest_gap, largest_move, finite = tick_outcome_into(
        effector_matrices[W_EA], delta_free, vectors[SCALE], x, vectors[X_PREVIOUS],
        vectors[LOWER], vectors[UPPER], proposed, gap)
    if not finite:
        return REJECTED, iterations, largest_gap, largest_move, False
    bounds_binding_into(matrices[TRACKING], vectors[TRACKING_GRADIENT], lower, upper, x,
                        buffers.tolerance, free)
    binding = False
    for j in range(free.size):
        binding = binding or free[j]
    vectors[ACTUATION, :] = proposed
    effector_positions = buffers.effector_positions
    if apply_step:
        apply_pending_step(buffers)
        effector_points_into(buffers.positions, buffers.rotations, buffers.effector_frames,
                             buffers.effector_offsets, effector_positions)
    else:
        # the linear model's prediction (paper eq. 11): the targets plus the predicted gaps
        for e in range(k):
            for i in range(3):
                effector_positions[e, i] = targets[e, i] + gap[3 * e + i]
    return SOLVED, iterations, largest_gap, largest_move, binding


@numba.njit(cache=True)
def apply_pending_step(buffers):
    """
    Apply the Newton step of the linearisation to the buffers' frames, in place.

    :func:`pending_step_into` on ``buffers.positions`` and ``buffers.rotations``.

    Parameters
    ----------
    buffers : cbha_inverse.core._kernels.tick_buffers.TickBuffers
        The tick's buffers (a solved linearisation).

    """
    pending_step_into(buffers, buffers.positions, buffers.rotations)


@numba.njit(cache=True)
def pending_step_into(buffers, positions, rotations):
    """
    Apply the Newton step of the buffers' linearisation to given frames, in place.

    ``dq = K⁻¹ r + K⁻¹ J_aᵀ (λ - λ_prev)`` with ``λ`` and ``λ_prev`` the buffers'
    ``vectors[ACTUATION]`` and ``vectors[LINEARISED]`` (their difference is written to
    ``vectors[CHANGE]``), by
    :func:`~cbha_inverse.core._kernels.retraction.apply_linear_step_into` on ``solved``: with
    ``half_solved`` the half-solves, then one backward sweep of the band factor (on its block
    profile with ``profiled``, as its Cholesky found it: no second check).

    Parameters
    ----------
    buffers : cbha_inverse.core._kernels.tick_buffers.TickBuffers
        The tick's buffers (a solved linearisation).
    positions : (n + 1, 3) ndarray  [m]
        Frame origins (updated; the buffers' or a copy).
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations (updated).

    """
    vectors, solved = buffers.vectors, buffers.solved
    change, actuation, linearised = vectors[CHANGE], vectors[ACTUATION], vectors[LINEARISED]
    for j in range(change.size):
        change[j] = actuation[j] - linearised[j]
    apply_linear_step_into(positions, rotations, solved[:, 0], solved[:, 1:], change,
                           buffers.max_rotation, buffers.increments,
                           band_rows(buffers.band, buffers.rhs.shape[0]),
                           buffers.half_solved[0], buffers.profiled[0])
