"""
The compiled steps of the static solver's Newton iteration (paper eq. 9), over one record.

:mod:`cbha_inverse.core.statics` solves ``r(q) = 0`` by Newton's method with a line search in
the links' deformation coordinates. Its compiled parts: :func:`newton_point` evaluates a state
(:func:`~cbha_inverse.core._kernels.evaluation.evaluate`, exact) and measures its residual
(:func:`~cbha_inverse.core._kernels.residual.residual_measures`); :func:`newton_direction`
solves Newton's equation with the exact tangent of that evaluation (its block LU,
:func:`~cbha_inverse.core._kernels.evaluation.factor_exact`) and maps the step to the
deformation coordinates (:func:`~cbha_inverse.core._kernels.retraction.deformation_step`);
:func:`newton_trial` moves the frames along it and evaluates them. The buffers are one
:class:`NewtonRecord` (fields :data:`NEWTON_FIELDS`), one per chain and actuators.
"""

from cbha_inverse.core._kernels.block_lu import block_lu_solve
from cbha_inverse.core._kernels.evaluation import evaluate, factor_exact
from cbha_inverse.core._kernels.records import define_record, Field, Record, RecordType
from cbha_inverse.core._kernels.residual import residual_measures
from cbha_inverse.core._kernels.retraction import deformation_step, deformed_poses
import numba
from numba.experimental import structref
import numpy as np

F8 = np.float64

NEWTON_FIELDS = (
    Field('system', 'record', 0, 'the equilibrium evaluator (evaluation.EquilibriumRecord)'),
    Field('actuation', F8, 1, '(m,) λ of the problem, at the full load [Pa, N]'),
    Field('scaled_actuation', F8, 1, '(m,) lam λ at the load factor lam'),
    Field('dead', F8, 1, '(6n,) constant loads of the problem, at the full load [N, N*m]'),
    Field('extra', F8, 1, '(6n,) user loads at the state, at the full load [N, N*m]'),
    Field('floor', F8, 1, '(n,) round-off level of the internal wrench at frames 1..n [N]',
          read_only=True),
    Field('frame_max', F8, 1, '(n,) largest scaled residual component of every frame [N]'),
    Field('residual', F8, 1, '(6n,) the residual of the last point [N, N*m]'),
    Field('step', F8, 2, '(6n, 1) the last Newton step [m, rad]'),
    Field('rest_rotations', F8, 3, '(n, 3, 3) Q0', read_only=True),
    Field('coordinates', F8, 2, '(n, 12) (u, φ, du, dφ) of the step, per link'),
)
"""The fields of :class:`NewtonRecord`."""


@structref.register
class NewtonRecordType(RecordType):
    """The numba type of :class:`NewtonRecord`."""


class NewtonRecord(Record):
    """The buffers of the static solver's Newton iterations (:data:`NEWTON_FIELDS`)."""

    __slots__ = ()


define_record(NewtonRecord, NewtonRecordType, NEWTON_FIELDS)


@numba.njit(cache=True)
def new_newton_record(*values):
    """Build a :class:`NewtonRecord` (fields in declaration order)."""
    return NewtonRecord(*values)


@numba.njit(cache=True)
def newton_point(newton, positions, rotations, load_factor, length, tolerance):
    """
    Evaluate a state at a load factor and return its residual's measures.

    ``r = f(q) + lam (f_dead + J_aᵀ λ + f_extra)``: the evaluation at ``lam λ`` (exact, its
    blocks into the system's ``values``), then
    :func:`~cbha_inverse.core._kernels.residual.residual_measures`, which writes ``residual``
    and returns the measures (``measure, merit, scaled_norm, norm, load_scale,
    within_roundoff``).

    Parameters
    ----------
    newton : NewtonRecord
        The buffers.
    positions : (n + 1, 3) ndarray  [m]
        Frame origins.
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations.
    load_factor : float
        ``lam``.
    length : float  [m]
        The chain's length (moments are divided by it in the measures).
    tolerance : float
        Relative tolerance of the convergence test.

    """
    scaled, actuation = newton.scaled_actuation, newton.actuation
    for j in range(scaled.size):
        scaled[j] = load_factor * actuation[j]
    evaluate(newton.system, positions, rotations, scaled, bool(True), bool(False))
    return residual_measures(newton.system.rhs, scaled, newton.dead, newton.extra, load_factor,
                             length, newton.floor, tolerance, newton.residual, newton.frame_max)


@numba.njit(cache=True)
def newton_direction(newton, positions, rotations):
    """
    Solve Newton's equation at the last point with its exact tangent; map the step to the links.

    ``K step = r``: the exact tangent of the last :func:`newton_point` (its blocks, at these
    frames) assembled and factored (:func:`~cbha_inverse.core._kernels.evaluation.factor_exact`)
    and solved (:func:`~cbha_inverse.core._kernels.block_lu.block_lu_solve`), then the step's
    deformation coordinates (:func:`~cbha_inverse.core._kernels.retraction.deformation_step`).

    Returns
    -------
    info : int
        0, or the block LU's failure (nothing else written).
    largest : float  [rad]
        The largest link rotation of the step (NaN unless ``info`` is 0).

    """
    system, step, residual = newton.system, newton.step, newton.residual
    info = factor_exact(system)
    if info != 0:
        return info, np.nan
    for row in range(residual.size):
        step[row, 0] = residual[row]
    block_lu_solve(system.exact_blocks[:step.shape[0] // 6], system.lu_pivots, step)
    return 0, deformation_step(positions, rotations, newton.rest_rotations,
                               step.reshape((step.shape[0] // 6, 6)), newton.coordinates)


@numba.njit(cache=True)
def newton_trial(newton, base_positions, base_rotations, alpha, positions, rotations,
                 load_factor, length, tolerance):
    """
    Move the frames along the step's deformation coordinates by ``alpha`` and evaluate them.

    ``positions`` and ``rotations`` receive the base frames advanced by ``alpha`` of
    ``coordinates`` (:func:`~cbha_inverse.core._kernels.retraction.deformed_poses`; frame 0 is
    kept), then :func:`newton_point`.
    """
    for i in range(positions.shape[0]):
        for j in range(3):
            positions[i, j] = base_positions[i, j]
            for k in range(3):
                rotations[i, j, k] = base_rotations[i, j, k]
    deformed_poses(newton.coordinates, alpha, newton.rest_rotations, positions, rotations)
    return newton_point(newton, positions, rotations, load_factor, length, tolerance)
