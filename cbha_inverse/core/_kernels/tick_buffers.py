"""
The control tick's buffers as one compiled object: what the tick's entries take (`docs/design.md`).

numba unboxes every argument of a compiled call at every call (a few tenths of a microsecond
per array), so an entry over the tick's ~40 arrays pays more for its arguments than for some of
its kernels. :class:`TickBuffers` is a numba StructRef holding them all (a reference-counted
record of the arrays, built once): the tick's entries (:mod:`cbha_inverse.core._kernels.tick`)
take it as one argument and read its fields. The arrays are those of
:class:`cbha_inverse.core.inverse.tick_data.TickData`, not copies: the Python side and the
compiled side read and write the same memory. The type lives in this module of its own so that
numba's on-disk cache of the entries finds it again in a new process.

Fields (:data:`FIELDS`, in the order of :func:`make_tick_buffers`; stacked rows in
:mod:`cbha_inverse.core._kernels.tick`)::

    positions (n + 1, 3) [m], rotations (n + 1, 3, 3)      the frames of the tick's state
    vectors (ACTUATOR_ROWS, m)                             actuator rows (constants, state, work)
    stiffness, rest_offsets, rest_rotations_t,             the link terms of
      cavity_wrench, cavity_stiffness                        links.link_pass
    cavity_columns (n, c) int                              nonzero cavity columns of every link
    link_work                                              workspace of the link pass
    external (6n,) [N, N*m]                                constant external wrenches
    cable_gains (m_c,), cable_offsets (P, 3) [m],          the cable group (empty without
      cable_frames (P,) int, cable_spans (4, S) int,         cables): gains, routing points,
      cable_points (2, P) int, cable_columns (m_c,) int      their frames, spans (start, end,
                                                             cable, frame pair), points (cable,
                                                             moment slot), actuator columns
    cable_work                                             workspace of the cable pass
    index (V,) int, slot_weights (V,)                      band slot and weight of every value
    counts (3,) int                                        link, cable pair, cable moment values
    values (V,)                                            the blocks of the evaluation
    band ((6n + 1) (kd + 1),)                              symmetric lower band (and a trash
                                                             row), then its factor
    rhs (6n, m + 1)                                        [r, J_aᵀ]
    solved (6n, m + 1)                                     L⁻¹ [r, J_aᵀ] (half_solved) or
                                                             K⁻¹ [r, J_aᵀ]
    matrices (MATRIX_ROWS, m, m)                           QP Hessians, W_aa, the QP's factor
    effector_matrices (2, 3k, m)                           W_ea, W_ea σ / ν
    gaps (3, 3k) [m]                                       offset, δ_free, predicted gap
    moved (3k, m + 1), levers (k, 3)                       workspace of the projection
    effector_columns (6n, 3k)                              L⁻¹ J_eᵀ (half_solved) or J_eᵀ
    half_solved (1,) bool                                  whether solved and effector_columns
                                                             hold half-solves by the band factor
    profiled (1,) bool                                     whether the band factor has the 6 x 6
                                                             block profile (band.frame_profile)
    effector_frames (k,) int, effector_offsets (k, 3) [m]  the effector points
    weights (2,)                                           ε_E, ε_P
    flags (2, m) int8                                      active set (warm start), pivots
    free (m,) bool                                         QP workspace, then the binding bounds
    qp_index (m,) int                                      QP workspace
    increments (n, 6)                                      workspace of the Newton step
    effector_positions (k, 3) [m]                          effector positions after the tick
    base (3,) [m], reach (k,) [m]                          the targets' check (base position,
                                                             largest reach of each effector)
    max_iterations int, tolerance float                    active-set limit, binding tolerance
    max_rotation float [rad]                               largest frame rotation of a step
"""

from types import SimpleNamespace

from llvmlite import ir
import numba
from numba.core import cgutils, types
from numba.core.extending import box, NativeValue, unbox
from numba.experimental import structref
import numpy as np

FIELDS = ('positions', 'rotations', 'vectors', 'stiffness', 'rest_offsets', 'rest_rotations_t',
          'cavity_wrench', 'cavity_stiffness', 'cavity_columns', 'link_work', 'external',
          'cable_gains', 'cable_offsets', 'cable_frames', 'cable_spans', 'cable_points',
          'cable_columns', 'cable_work', 'index', 'slot_weights', 'counts', 'values', 'band',
          'rhs', 'solved', 'matrices', 'effector_matrices', 'gaps', 'moved', 'effector_columns',
          'half_solved', 'profiled', 'effector_frames', 'effector_offsets', 'levers', 'weights',
          'flags', 'free', 'qp_index', 'increments', 'effector_positions', 'base', 'reach',
          'max_iterations', 'tolerance', 'max_rotation')
"""Field names, in the order of :func:`make_tick_buffers`."""

EVALUATION_FIELDS = FIELDS[3:24]
"""The fields of the fused evaluation (``stiffness`` ... ``rhs``,
:meth:`cbha_inverse.core.system.EquilibriumSystem.fused_terms`)."""

# element type, dimensions and whether read-only of every field of EVALUATION_FIELDS (for the
# placeholders of a scene without the fused evaluation: the same compiled type)
_EVALUATION_TYPES = (
    (np.float64, 3, True), (np.float64, 2, True), (np.float64, 3, False),
    (np.float64, 3, False), (np.float64, 4, False), (np.int64, 2, False),
    (np.float64, 1, False), (np.float64, 1, False), (np.float64, 1, False),
    (np.float64, 2, False), (np.int64, 1, False), (np.int64, 2, False), (np.int64, 2, False),
    (np.int64, 1, False), (np.float64, 1, False), (np.int64, 1, False),
    (np.float64, 1, False), (np.int64, 1, False), (np.float64, 1, False),
    (np.float64, 1, False), (np.float64, 2, False))


@structref.register
class TickBuffersType(types.StructRef):
    """The numba type of :class:`TickBuffers` (one per combination of field types)."""

    def preprocess_fields(self, fields):
        """Keep the field types as given (arrays keep their layout and read-only flag)."""
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class TickBuffers(structref.StructRefProxy):
    """
    The tick's buffers as one compiled object (build it with :func:`make_tick_buffers`).

    Python reads the arrays through the object that built it
    (:class:`cbha_inverse.core.inverse.tick_data.TickData`); compiled code reads the fields of
    the module docstring.
    """

    __slots__ = ()

    def __new__(cls, *values):
        """Build the object from the fields' values, in the order of :data:`FIELDS`."""
        return make_tick_buffers(*values)


structref.define_constructor(TickBuffers, TickBuffersType, list(FIELDS))


@box(TickBuffersType)
def _box_tick_buffers(typ, val, c):
    """Wrap the compiled object's meminfo in a :class:`TickBuffers` (as numba's StructRef)."""
    meminfo = cgutils.create_struct_proxy(typ)(c.context, c.builder, value=val).meminfo
    boxed_meminfo = c.box(types.MemInfoPointer(types.voidptr), meminfo)
    constructor = c.pyapi.unserialize(c.pyapi.serialize_object(TickBuffers._numba_box_))
    type_object = c.pyapi.unserialize(c.pyapi.serialize_object(typ))
    boxed = c.pyapi.call_function_objargs(constructor, [type_object, boxed_meminfo])
    for reference in (constructor, type_object, boxed_meminfo):
        c.pyapi.decref(reference)
    return boxed


@unbox(TickBuffersType)
def _unbox_tick_buffers(typ, obj, c):
    """
    Read the meminfo of a :class:`TickBuffers` (as numba's StructRef, by an interned name).

    numba's own unboxing looks the attribute up by a new string at every call, and CPython's
    type attribute cache keeps a reference to every such string it has seen (by address): a
    tick would then leave a few bytes behind now and then. The interned name is one object.
    """
    intern = c.pyapi._get_function(ir.FunctionType(c.pyapi.pyobj, [c.pyapi.cstring]),
                                   name='PyUnicode_InternFromString')
    name = c.builder.call(intern, [c.context.insert_const_string(c.builder.module, '_meminfo')])
    meminfo_object = c.pyapi.object_getattr(obj, name)
    c.pyapi.decref(name)
    meminfo = c.unbox(types.MemInfoPointer(types.voidptr), meminfo_object).value
    value = cgutils.create_struct_proxy(typ)(c.context, c.builder)
    value.meminfo = meminfo
    c.pyapi.decref(meminfo_object)
    return NativeValue(value._getvalue())


def make_tick_buffers(*values):
    """
    Return a :class:`TickBuffers` of the given arrays (no copy) and scalars.

    With numba's JIT off (``NUMBA_DISABLE_JIT=1``, the kernels' coverage run) the kernels run as
    Python and read the same fields of a plain namespace instead.

    Parameters
    ----------
    *values
        The fields of the module docstring, in the order of :data:`FIELDS`.

    Returns
    -------
    TickBuffers or types.SimpleNamespace

    """
    if numba.config.DISABLE_JIT:
        return SimpleNamespace(**dict(zip(FIELDS, values, strict=True)))
    return _new_tick_buffers(*values)


@numba.njit(cache=True)
def _new_tick_buffers(positions, rotations, vectors, stiffness, rest_offsets, rest_rotations_t,
                      cavity_wrench, cavity_stiffness, cavity_columns, link_work, external,
                      cable_gains, cable_offsets, cable_frames, cable_spans, cable_points,
                      cable_columns, cable_work, index, slot_weights, counts, values, band, rhs,
                      solved, matrices, effector_matrices, gaps, moved, effector_columns,
                      half_solved, profiled, effector_frames, effector_offsets, levers, weights,
                      flags, free, qp_index, increments, effector_positions, base, reach,
                      max_iterations, tolerance, max_rotation):
    """Build the compiled object of :func:`make_tick_buffers`."""
    return TickBuffers(positions, rotations, vectors, stiffness, rest_offsets, rest_rotations_t,
                       cavity_wrench, cavity_stiffness, cavity_columns, link_work, external,
                       cable_gains, cable_offsets, cable_frames, cable_spans, cable_points,
                       cable_columns, cable_work, index, slot_weights, counts, values, band, rhs,
                       solved, matrices, effector_matrices, gaps, moved, effector_columns,
                       half_solved, profiled, effector_frames, effector_offsets, levers, weights,
                       flags, free, qp_index, increments, effector_positions, base, reach,
                       max_iterations, tolerance, max_rotation)


def placeholder_evaluation(rhs):
    """
    Return empty arrays for :data:`EVALUATION_FIELDS` of a scene without the fused evaluation.

    They have the element types, dimensions and read-only flags of the fused evaluation's own
    (so the tick's entries keep one compiled type); ``rhs`` is the system's.

    Parameters
    ----------
    rhs : (6n, m + 1) ndarray
        The evaluator's right-hand sides (the last field).

    Returns
    -------
    tuple of ndarray

    """
    arrays = []
    for dtype, ndim, read_only in _EVALUATION_TYPES[:-1]:
        array = np.zeros((0,) * ndim, dtype=dtype)
        array.flags.writeable = not read_only
        arrays.append(array)
    return tuple(arrays) + (rhs,)
