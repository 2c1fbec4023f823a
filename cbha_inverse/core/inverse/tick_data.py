"""
The buffers of the control tick: the data half of the solver's model / data split.

:class:`TickData` holds every array the compiled entries of a tick write
(:func:`cbha_inverse.core._kernels.tick.control_tick`, which runs
:func:`~cbha_inverse.core._kernels.tick.linearise_tick` and
:func:`~cbha_inverse.core._kernels.tick.solve_tick`) next to the constant arrays of the model
they read, held by one compiled object built once
(:class:`cbha_inverse.core._kernels.tick_buffers.TickBuffers`, :attr:`TickData.buffers`): a tick
passes it without building anything.
The solver (:class:`cbha_inverse.core.inverse.solver.InverseSolver`) owns one; the model
(chain, actuators, effectors, options) never changes, the data changes every tick. Named
attributes are views of the stacked arrays (rows in :mod:`cbha_inverse.core._kernels.tick`),
so the Python side and the compiled side read the same memory.
"""

import functools
import math

from cbha_inverse.core._kernels import tick as rows
from cbha_inverse.core._kernels.tick_buffers import (EVALUATION_FIELDS, make_tick_buffers,
                                                     placeholder_evaluation)
from cbha_inverse.core.inverse.qp import QPMatrices
import numpy as np


class TickData:
    """
    Preallocated buffers of one solver's ticks, and the compiled object that holds them.

    Parameters
    ----------
    system : cbha_inverse.core.system.EquilibriumSystem
        The solver's evaluator (its assembly index and buffers are shared).
    effectors : cbha_inverse.core.actuation.effectors.PointEffectors
        The effector points (``k``).
    scale, lower_bounds, upper_bounds : (m,) ndarray
        ``σ`` and the actuator bounds.
    rate_limit : (m,) ndarray or None
        Largest change per tick (``None``: no limit, an infinite rate for the compiled QP).
    options : cbha_inverse.core.inverse.results.InverseOptions
        Energy and proximal weights, rotation step.
    max_iterations : int
        Active-set iteration limit.
    base : (3,) ndarray, optional  [m]
        Base position (the targets' check of
        :func:`~cbha_inverse.core._kernels.tick.control_tick`; default: the origin).
    reach : (k,) ndarray, optional  [m]
        Largest distance (max-abs component) of each effector from the base (default:
        infinite).

    Attributes
    ----------
    positions : (n + 1, 3) ndarray  [m]
        Frame origins of the solver's state.
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations of the solver's state.
    actuation : (m,) ndarray  [N or Pa]
        The current actuation.
    linearised : (m,) ndarray
        ``λ_prev`` of the current linearisation.
    solved : (6n, m + 1) ndarray
        ``L⁻¹ [r, J_aᵀ]`` of the current linearisation (the forward sweep of its band factor
        ``K = L Lᵀ``), or ``K⁻¹ [r, J_aᵀ]`` after the fallback chain (:attr:`half_solved`).
    half_solved : (1,) bool ndarray
        Whether :attr:`solved` holds the band factor's half-solves (the compiled entries read
        it; the fallback chain clears it before it writes ``K⁻¹ [r, J_aᵀ]``).
    profiled : (1,) bool ndarray
        Whether the band factor has the 6 x 6 block profile (written by the compiled
        linearisation, read by the backward sweep of its step).
    offset : (3k,) ndarray  [m]
        ``p_e + J_e K⁻¹ r - W_ea λ_prev`` (so ``δ_free = offset - target``).
    w_ea : (3k, m) ndarray
        ``W_ea`` of the current linearisation.
    gap : (3k,) ndarray  [m]
        The last solved tick's predicted gap ``W_ea λ + δ_free``.
    mask : (m,) bool ndarray
        After a solved compiled tick, the binding bounds.
    state : (m,) int8 ndarray
        The active set (warm start of the exact QP).
    effector_positions : (k, 3) ndarray  [m]
        Effector positions after a solved compiled tick: of the state when it applied its
        step, else the linear model's prediction.
    matrices : cbha_inverse.core.inverse.qp.QPMatrices
        The current QP matrices, as views.
    rhs : (6n, m + 1) ndarray
        ``[r, J_aᵀ]`` (the evaluator's buffer).
    external : (6n,) ndarray  [N, N*m]
        The external wrenches the fused linearisation adds to ``r``.
    band : ((6n + 1) (kd + 1),) ndarray
        The symmetric lower band, then its factor, of the fused linearisation.
    fused : bool
        Whether the linearisation runs as one compiled entry (see
        :meth:`cbha_inverse.core.system.EquilibriumSystem.fused_terms`; without it the
        evaluation's fields of :attr:`buffers` are empty placeholders).
    buffers : cbha_inverse.core._kernels.tick_buffers.TickBuffers
        Every array above and the model's constant arrays, the one argument of the compiled
        entries (:mod:`cbha_inverse.core._kernels.tick`).
    increments : (n, 6) ndarray
        Workspace of :func:`cbha_inverse.core._kernels.retraction.apply_linear_step_into`.

    """

    def __init__(self, system, effectors, scale, lower_bounds, upper_bounds, rate_limit,
                 options, max_iterations, base=None, reach=None):
        """Allocate every buffer and build the compiled object."""
        n, m, k = system.n, system.m, effectors.n_effectors
        base = np.zeros(3) if base is None else np.array(base, dtype=float)
        reach = np.full(k, math.inf) if reach is None else np.array(reach, dtype=float)
        self.positions = np.zeros((n + 1, 3))
        self.rotations = np.zeros((n + 1, 3, 3))
        self.vectors = np.zeros((rows.ACTUATOR_ROWS, m))
        self.vectors[rows.SCALE] = scale
        self.vectors[rows.LOWER] = lower_bounds
        self.vectors[rows.UPPER] = upper_bounds
        self.vectors[rows.RATE] = math.inf if rate_limit is None else rate_limit
        self.actuation = self.vectors[rows.ACTUATION]
        self.linearised = self.vectors[rows.LINEARISED]
        self.solved = np.zeros((6 * n, m + 1))
        self.half_solved = np.zeros(1, dtype=np.bool_)
        self.profiled = np.zeros(1, dtype=np.bool_)
        self.rhs = system.rhs
        self.matrices_stack = np.zeros((rows.MATRIX_ROWS, m, m))
        self.effector_matrices = np.zeros((2, 3 * k, m))
        self.gaps = np.zeros((3, 3 * k))
        self.offset, self.gap = self.gaps[rows.OFFSET], self.gaps[rows.GAP]
        self.w_ea = self.effector_matrices[rows.W_EA]
        self.flags = np.zeros((2, m), dtype=np.int8)
        self.state = self.flags[rows.STATE]
        self.mask = np.zeros(m, dtype=np.bool_)
        self.effector_positions = np.zeros((k, 3))
        self.matrices = QPMatrices(self.matrices_stack[rows.HESSIAN],
                                   self.matrices_stack[rows.TRACKING],
                                   self.effector_matrices[rows.WEIGHTED_W],
                                   self.vectors[rows.SCALE], options.proximal_weight)
        frames = np.ascontiguousarray(effectors.frames, dtype=np.int64)
        offsets = np.ascontiguousarray(effectors.offsets, dtype=float)
        weights = np.array([options.energy_weight, options.proximal_weight], dtype=float)
        max_rotation = (math.inf if options.max_rotation_step is None
                        else float(options.max_rotation_step))
        self.max_rotation = max_rotation
        terms = system.fused_terms()
        self.fused = terms is not None
        if terms is None:
            terms = placeholder_evaluation(self.rhs)
        self.external = terms[EVALUATION_FIELDS.index('external')]
        self.band = terms[EVALUATION_FIELDS.index('band')]
        self.increments = np.zeros((n, 6))
        self.buffers = make_tick_buffers(
            self.positions, self.rotations, self.vectors, *terms, self.solved,
            self.matrices_stack, self.effector_matrices, self.gaps, np.zeros((3 * k, m + 1)),
            np.zeros((6 * n, 3 * k)), self.half_solved, self.profiled, frames, offsets,
            np.zeros((k, 3)), weights, self.flags, self.mask, np.zeros(m, dtype=np.int64),
            self.increments, self.effector_positions, base, reach, int(max_iterations), 1e-6,
            max_rotation)

    @functools.cached_property
    def tick_entry(self):
        """
        Return the compiled ``control_tick`` (targets, buffers and four flags).

        ``control_tick(targets, buffers, materialise, linearise, cholesky, apply_step)``; the
        targets must be a C-contiguous float (k, 3) array
        (:func:`cbha_inverse.core._kernels.tick.compiled_entry`).
        """
        return rows.compiled_entry(rows.control_tick, self.effector_positions, self.buffers,
                                   True, True, True, True)

    @functools.cached_property
    def linearise_entry(self):
        """Return the compiled ``linearise_tick(buffers, cholesky)`` (``tick.compiled_entry``)."""
        return rows.compiled_entry(rows.linearise_tick, self.buffers, True)

    @functools.cached_property
    def solve_entry(self):
        """
        Return the compiled ``solve_tick(targets, buffers, apply_step)``.

        The targets must be a C-contiguous float (k, 3) array
        (:func:`cbha_inverse.core._kernels.tick.compiled_entry`).
        """
        return rows.compiled_entry(rows.solve_tick, self.effector_positions, self.buffers, True)

    @functools.cached_property
    def step_entry(self):
        """Return the compiled ``apply_pending_step(buffers)`` (``tick.compiled_entry``)."""
        return rows.compiled_entry(rows.apply_pending_step, self.buffers)

    @functools.cached_property
    def pending_entry(self):
        """
        Return the compiled ``pending_step_into(buffers, positions, rotations)``.

        The frames must be C-contiguous float arrays of the shapes of :attr:`positions` and
        :attr:`rotations` (``tick.compiled_entry``).
        """
        return rows.compiled_entry(rows.pending_step_into, self.buffers, self.positions,
                                   self.rotations)

    def project_factor(self, factor):
        """
        Solve ``K⁻¹ [r, J_aᵀ]`` by a factor of the fallback chain and project it.

        The solves are then full solves, not the band factor's half-solves (:attr:`half_solved`
        cleared), and :func:`cbha_inverse.core._kernels.tick.project_tick` forms ``W_ea``,
        ``W_aa`` and the QP matrices from them.

        Parameters
        ----------
        factor : object
            A factor of
            :meth:`cbha_inverse.core.system.EquilibriumSystem.fallback_factors` (``solve``).

        Returns
        -------
        float  [N, N*m]
            ``|r|``.

        """
        self.half_solved[0] = False
        self.solved[:] = factor.solve(self.rhs)
        return rows.project_tick(self.buffers)
