"""
The buffers of the control tick: the data half of the solver's model / data split.

:class:`TickData` allocates every array the compiled tick reads and writes
(:func:`cbha_inverse.core._kernels.tick.control_tick`) and holds them in one compiled record
(:class:`cbha_inverse.core._kernels.tick.TickRecord`, :attr:`TickData.record`), built once: a
tick passes it without building anything. Its attributes are the record's arrays themselves, so
the Python side and the compiled side read and write the same memory. The solver
(:class:`cbha_inverse.core.inverse.solver.InverseSolver`) owns one, the shape estimator another.
"""

import math

from cbha_inverse.core._kernels import tick as kernels
from cbha_inverse.core._kernels.records import compiled_entry, make_record, RecordOwner
from cbha_inverse.core.inverse.obstacle_rows import obstacle_rows_record
from cbha_inverse.core.inverse.qp import QPMatrices
import numpy as np

BINDING_TOLERANCE = 1e-6
"""Tolerance of the binding bounds (dimensionless actuation and tracking gradient)."""


class TickData(RecordOwner):
    """
    Preallocated buffers of one solver's ticks, and the compiled record that holds them.

    Parameters
    ----------
    system : cbha_inverse.core.system.EquilibriumSystem
        The solver's evaluator (its record is the tick's ``system``).
    effectors : cbha_inverse.core.actuation.effectors.PointEffectors
        The effectors (``k``; ``3k + o`` rows with the rotational rows).
    scale, lower_bounds, upper_bounds : (m,) ndarray
        ``σ`` and the actuator bounds.
    rate_limit : (m,) ndarray or None
        Largest change per tick (``None``: no limit, an infinite rate).
    options : cbha_inverse.core.inverse.results.InverseOptions
        Energy and proximal weights, rotation step.
    max_iterations : int
        Active-set iteration limit.
    base : (3,) ndarray, optional  [m]
        Base position (the targets' check; default: the origin).
    reach : (k,) ndarray, optional  [m]
        Largest distance (max-abs component) of each effector from the base (default:
        infinite).

    Attributes
    ----------
    record : cbha_inverse.core._kernels.tick.TickRecord
        The compiled record (:data:`cbha_inverse.core._kernels.tick.TICK_FIELDS`).
    arrays : dict of str to ndarray
        Its arrays by field name; each is also an attribute of this object (``positions``,
        ``actuation``, ``solved``, ``w_ea``, ...).
    matrices : cbha_inverse.core.inverse.qp.QPMatrices
        The current QP matrices, as views of the record's (for the QP solvers in Python).

    """

    def __init__(self, system, effectors, scale, lower_bounds, upper_bounds, rate_limit,
                 options, max_iterations, base=None, reach=None):
        """Allocate every buffer and build the compiled record."""
        n, m, k = system.n, system.m, effectors.n_effectors
        # the rows of J_e: 3k position rows, then o rotational rows (docs/effectors.md)
        rows, o = effectors.n_rows, effectors.orientation_effectors.size
        rate = np.full(m, math.inf) if rate_limit is None else rate_limit
        self.arrays = {
            'positions': np.zeros((n + 1, 3)), 'rotations': np.zeros((n + 1, 3, 3)),
            'actuation': np.zeros(m), 'linearised': np.zeros(m),
            'scale': _floats(scale, m), 'lower': _floats(lower_bounds, m),
            'upper': _floats(upper_bounds, m), 'rate': _floats(rate, m),
            'effector_frames': np.ascontiguousarray(effectors.frames, dtype=np.int64),
            'effector_offsets': np.ascontiguousarray(effectors.offsets, dtype=float),
            'effector_kinds': np.array(effectors.kind_codes, dtype=np.int64),
            'effector_axes': np.array(effectors.axes, dtype=float),
            'orientation_effectors': np.array(effectors.orientation_effectors, dtype=np.int64),
            'orientation_axes': np.array(effectors.orientation_axes, dtype=float).reshape(o, 3),
            'row_weights': np.array(effectors.row_weights, dtype=float),
            'base': _floats(np.zeros(3) if base is None else base, 3),
            'reach': _floats(np.full(k, math.inf) if reach is None else reach, k),
            'target_directions': np.array(effectors.axes, dtype=float),
            'target_rotations': np.tile(np.eye(3), (k, 1, 1)),
            'solved': np.zeros((6 * n, m + 1)), 'column_starts': np.zeros(m + 1, dtype=np.int64),
            'effector_columns': np.zeros((6 * n, rows)),
            'effector_starts': np.zeros(rows, dtype=np.int64),
            'half_solved': np.zeros(1, dtype=np.bool_), 'levers': np.zeros((k, 3)),
            'orientation_directions': np.zeros((o, 3)),
            'moved': np.zeros((rows, m + 1)), 'equilibrium_gap': np.zeros(1),
            'gap_limit': np.full(1, math.inf), 'w_ea': np.zeros((rows, m)),
            'w_aa': np.zeros((m, m)), 'offset': np.zeros(rows),
            'hessian': np.zeros((m, m)), 'tracking': np.zeros((m, m)),
            'weighted_w': np.zeros((rows, m)), 'tracking_norm': np.ones(1),
            'orientation_errors': np.zeros((k, 3)),
            'relative_rotation': np.zeros((3, 3)),
            'delta_free': np.zeros(rows),
            'gradient': np.zeros(m), 'tracking_gradient': np.zeros(m),
            'box_lower': np.zeros(m), 'box_upper': np.zeros(m), 'x_previous': np.zeros(m),
            'x': np.zeros(m), 'active_set': np.zeros(m, dtype=np.int8),
            'pivot': np.zeros(m, dtype=np.int8), 'free': np.zeros(m, dtype=np.bool_),
            'qp_index': np.zeros(m, dtype=np.int64), 'qp_factor': np.zeros((m, m)),
            'qp_solve': np.zeros(m), 'proposed': np.zeros(m), 'gap': np.zeros(rows),
            'orientation_lengths': np.array(effectors.orientation_lengths, dtype=float),
            'orientation_gap': np.full(2, math.nan),
            'change': np.zeros(m), 'increments': np.zeros((n, 6)),
            'effector_positions': np.zeros((k, 3))}
        self.max_rotation = (math.inf if options.max_rotation_step is None
                             else float(options.max_rotation_step))
        # no obstacles until ObstacleRows attaches its record (attach_rows)
        self._no_rows = obstacle_rows_record(n, m)[0]
        self._hold(make_record(
            kernels.TickRecord, kernels.new_tick_record, system=system.record,
            rows=self._no_rows,
            energy_weight=options.energy_weight, proximal_weight=options.proximal_weight,
            max_iterations=int(max_iterations), tolerance=BINDING_TOLERANCE,
            max_rotation=self.max_rotation, **self.arrays), self.arrays)
        self.system = system
        self.matrices = QPMatrices(self.hessian, self.tracking, self.weighted_w, self.scale,
                                   options.proximal_weight)
        self._entries = {}

    def entry(self, name, examples=None):
        """
        Return a compiled entry of :mod:`cbha_inverse.core._kernels.tick` for this record.

        ``'control_tick'`` (``targets, record, materialise, linearise, solve, apply_step``; the
        targets a C-contiguous float (k, 3) array), ``'pending_step_into'`` (``record,
        positions, rotations``: C-contiguous float frames), ``'project_tick'`` (``record``),
        ``'free_gaps_of'`` (``targets, record``: ``delta_free`` of the targets) or
        ``'orientation_gap_of'`` (``record``), or another entry of the module typed by
        ``examples`` (its example arguments, e.g. ``'add_entering_rows'``);
        without numba's per-call type dispatch
        (:func:`cbha_inverse.core._kernels.records.compiled_entry`).
        """
        entry = self._entries.get(name)
        if entry is None:
            if examples is None:
                examples = {'control_tick': (self.effector_positions, self.record, True, True,
                                             True, True),
                            'pending_step_into': (self.record, self.positions, self.rotations),
                            'project_tick': (self.record,),
                            'free_gaps_of': (self.effector_positions, self.record),
                            'orientation_gap_of': (self.record,)}[name]
            entry = compiled_entry(getattr(kernels, name), *examples)
            self._entries[name] = entry
        return entry

    def attach_rows(self, rows=None):
        """
        Make an obstacle rows record the tick's ``rows`` (None: the record without obstacles).

        Parameters
        ----------
        rows : cbha_inverse.core._kernels.obstacle_rows.ObstacleRowsRecord, optional
            Built by :func:`cbha_inverse.core.inverse.obstacle_rows.obstacle_rows_record` for
            this solver's ``n`` and ``m``.

        """
        rows = self._no_rows if rows is None else rows
        kernels.attach_rows(self.record, rows)
        # the Python side's fields (a compiled record's; with the JIT off, the namespace is it)
        values = getattr(self.record, '_values', None)
        if values is not None:
            values['rows'] = rows

    def project_factor(self, factor):
        """
        Solve ``K⁻¹ [r, J_aᵀ]`` by a factor of the fallback chain and project it.

        The solves are then full solves, not the band factor's half-solves (``half_solved``
        cleared), and :func:`cbha_inverse.core._kernels.tick.project_tick` forms ``W_ea``,
        ``W_aa`` and the QP matrices from them.

        Parameters
        ----------
        factor : cbha_inverse.core.linalg.factors.TangentFactor
            A factor of :meth:`cbha_inverse.core.system.EquilibriumSystem.fallback_factors`.

        Returns
        -------
        float  [N, N*m]
            ``|r|``.

        """
        self.half_solved[0] = False
        self.linearised[:] = self.actuation
        self.solved[:] = factor.solve(self.system.rhs)
        return self.entry('project_tick')(self.record)


def _floats(values, size):
    """Return ``values`` as a new C-ordered float array of ``size`` entries."""
    return np.array(np.broadcast_to(np.asarray(values, dtype=float), (size,)))
