"""
The compiled evaluation of the chain's equilibrium (paper eq. 9): residual, ``J_aᵀ``, tangents.

:func:`evaluate` is the one evaluation of ``r(q) = f(q) + f_ext + J_a(q)ᵀ λ`` and of its tangent,
for the control tick, the static solver, the scenes' forward model, the plant and the shape
estimator: the links with their condensed cavities
(:func:`~cbha_inverse.core._kernels.links.link_pass`), the cables
(:func:`~cbha_inverse.core._kernels.cables.cable_pass`), the skinned-mesh cavities
(:func:`~cbha_inverse.core._kernels.mesh_cavities.mesh_cavity_pass`) and the constant external
wrenches. Its terms and buffers are one :class:`EquilibriumRecord` (fields
:data:`EQUILIBRIUM_FIELDS`), built by :class:`cbha_inverse.core.system.EquilibriumSystem`.

The tangent's 12 x 12 blocks (one per link, one per frame pair of cable spans) and 3 x 3 blocks
(cable point moments) are kept in ``values``; a constant index adds them into either storage:
the block band of the symmetric part (:func:`assemble_symmetric`, the block Cholesky of
:mod:`cbha_inverse.core._kernels.block_band`) or the blocks of the exact tangent
(:func:`assemble_exact`, the block LU of :mod:`cbha_inverse.core._kernels.block_lu`). The control
tick's evaluation adds the links' symmetric parts straight into the block band instead.

Compiled callers pass the flags ``exact`` and ``into_band`` as run-time values (``bool(True)``,
not ``True``): numba compiles a separate copy of a function, and of every function it calls,
for each literal argument.
"""

from cbha_inverse.core._kernels.assembly import scatter_add, scatter_more
from cbha_inverse.core._kernels.block_band import block_cholesky
from cbha_inverse.core._kernels.block_lu import block_lu
from cbha_inverse.core._kernels.cables import cable_pass
from cbha_inverse.core._kernels.links import link_pass
from cbha_inverse.core._kernels.mesh_cavities import mesh_cavity_pass
from cbha_inverse.core._kernels.records import define_record, Field, Record, RecordType
import numba
from numba.experimental import structref
import numpy as np

F8, I8 = np.float64, np.int64

EQUILIBRIUM_FIELDS = (
    # the links (n of them) and their condensed cavities (c = m columns, or none)
    Field('stiffness', F8, 3, '(n, 6, 6) link stiffness K [N/m, N, N*m/rad]', read_only=True),
    Field('rest_offsets', F8, 2, '(n, 3) d0, frame b in frame a at rest [m]', read_only=True),
    Field('rest_rotations_t', F8, 3, '(n, 3, 3) Q0ᵀ, the rest rotation of b in a, transposed',
          read_only=True),
    Field('cavity_wrench', F8, 3, '(n, c, 6) G0 per link and actuator [N/Pa, N*m/Pa]',
          read_only=True),
    Field('cavity_stiffness', F8, 4, '(n, c, 6, 6) H per link and actuator', read_only=True),
    Field('cavity_columns', I8, 2, '(n, c) the nonzero cavity columns per link, then -1',
          read_only=True),
    # every cable of the scene: P routing points, S spans
    Field('cable_gains', F8, 1, '(m_c,) force gain of every cable [-]', read_only=True),
    Field('cable_columns', I8, 1, '(m_c,) actuator column of every cable', read_only=True),
    Field('cable_frames', I8, 1, '(P,) frame of every routing point', read_only=True),
    Field('cable_offsets', F8, 2, '(P, 3) routing points in their frame [m]', read_only=True),
    Field('point_owner', I8, 1, '(P,) cable of every point', read_only=True),
    Field('point_slot', I8, 1, '(P,) moment block of every point', read_only=True),
    Field('span_start', I8, 1, '(S,) first point of every span', read_only=True),
    Field('span_end', I8, 1, '(S,) second point of every span', read_only=True),
    Field('span_owner', I8, 1, '(S,) cable of every span', read_only=True),
    Field('span_pair', I8, 1, '(S,) frame-pair block of every span', read_only=True),
    # the skinned-mesh cavities: V vertices, T triangles, c_m cavities
    Field('mesh_frame_a', I8, 1, '(V,) lower frame of every vertex', read_only=True),
    Field('mesh_local_a', F8, 2, '(V, 3) vertex in the lower frame [m]', read_only=True),
    Field('mesh_local_b', F8, 2, '(V, 3) vertex in the upper frame [m]', read_only=True),
    Field('mesh_weight_b', F8, 1, '(V,) skinning weight of the upper frame', read_only=True),
    Field('mesh_triangles', I8, 2, '(T, 3) vertices of every triangle', read_only=True),
    Field('mesh_owner', I8, 1, '(V,) cavity of every vertex', read_only=True),
    Field('mesh_gains', F8, 1, '(c_m,) force gain of every mesh cavity [-]', read_only=True),
    Field('mesh_columns', I8, 1, '(c_m,) actuator column of every mesh cavity', read_only=True),
    # loads and the assembly of the tangent's blocks into the bands
    Field('external', F8, 1, '(6n,) external wrenches on frames 1..n [N, N*m]'),
    Field('index', I8, 1, '(V_b,) slot of every block value in the flat block band',
          read_only=True),
    Field('weights', F8, 1, '(V_b,) its weight (1 on the diagonal, 1/2 off it)', read_only=True),
    Field('exact_index', I8, 1, '(V_b,) slot of every block value in the flat exact blocks',
          read_only=True),
    Field('pair_start', int, 0, 'first value of the cable span blocks (after the links)'),
    Field('moment_start', int, 0, 'first value of the cable point moment blocks'),
    Field('moment_count', int, 0, 'number of cable point moment blocks'),
    # buffers of one evaluation
    Field('rhs', F8, 2, '(6n, m + 1) [r, J_aᵀ] [N, N*m]'),
    Field('values', F8, 1, '(V_b,) the tangent blocks: links (n 12 x 12), spans, moments'),
    Field('blocks', F8, 4, '(n + 1, B + 1, 6, 6) symmetric block band, last: base-frame trash'),
    Field('exact_blocks', F8, 4, "(n + 1, 2B + 1, 6, 6) exact tangent's blocks, last: trash"),
    Field('lu_pivots', I8, 2, '(n, 6) row interchanges of its LU within the diagonal blocks'),
    # scratch of the link pass (one link at a time)
    Field('link_difference', F8, 1, '(3,) x_b - x_a [m]'),
    Field('link_relative', F8, 2, '(3, 3) R_aᵀ R_b Q0ᵀ'),
    Field('link_delta', F8, 1, '(6,) δ [m, rad]'),
    Field('link_stress', F8, 1, '(6,) K δ [N, N*m]'),
    Field('link_jl_inverse', F8, 2, '(3, 3) Jl⁻¹(φ)'),
    Field('link_weighted', F8, 2, '(6, 6) Bᵀ K less the cavity load stiffness'),
    Field('link_tangent', F8, 2, '(6, 6) the local tangent M'),
    Field('link_local', F8, 2, '(6, m + 1) local wrenches (column 0, then per unit λ)'),
    Field('link_world', F8, 2, '(6, m + 1) the same in world axes'),
    Field('link_block', F8, 2, '(12, 12) the world tangent of the pair'),
    # scratch of the cable pass
    Field('cable_levers', F8, 2, '(P, 3) R_f o of every point [m]'),
    Field('cable_points', F8, 2, '(P, 3) world routing points [m]'),
    Field('cable_forces', F8, 2, '(P, 3) force per unit tension of every point [-]'),
    Field('span_units', F8, 2, '(S, 3) unit vector of every span'),
    Field('span_lengths', F8, 1, '(S,) length of every span [m]'),
    Field('pair_sums', F8, 4, '(n_pairs, 6, 3, 3) span products summed per frame pair'),
    Field('span_projection', F8, 2, '(3, 3) g t / l (I - u uᵀ) of a span [N/m]'),
    Field('start_hat', F8, 2, '(3, 3) hat of its start lever'),
    Field('end_hat', F8, 2, '(3, 3) hat of its end lever'),
    Field('start_product', F8, 2, '(3, 3) start hat times projection'),
    Field('end_product', F8, 2, '(3, 3) end hat times projection'),
    # scratch of the mesh cavity pass
    Field('mesh_points', F8, 2, '(V, 3) skinned vertices [m]'),
    Field('mesh_levers_a', F8, 2, '(V, 3) R_a a [m]'),
    Field('mesh_levers_b', F8, 2, '(V, 3) R_b b [m]'),
    Field('mesh_forces', F8, 2, '(V, 3) vertex forces per unit pressure [m^2]'),
    Field('mesh_wrenches', F8, 3, '(c_m, n + 1, 6) frame wrenches per unit pressure'),
)
"""The fields of :class:`EquilibriumRecord`."""


@structref.register
class EquilibriumRecordType(RecordType):
    """The numba type of :class:`EquilibriumRecord`."""


class EquilibriumRecord(Record):
    """The terms and buffers of one equilibrium evaluator (:data:`EQUILIBRIUM_FIELDS`)."""

    __slots__ = ()


define_record(EquilibriumRecord, EquilibriumRecordType, EQUILIBRIUM_FIELDS)


@numba.njit(cache=True)
def new_equilibrium_record(*values):
    """Build an :class:`EquilibriumRecord` (fields in declaration order)."""
    return EquilibriumRecord(*values)


@numba.njit(cache=True)
def evaluate(system, positions, rotations, actuation, exact, into_band):
    """
    Evaluate the residual, ``J_aᵀ`` and the tangent's blocks at a state, in place.

    ``system.rhs`` receives ``[r, J_aᵀ]``: column 0 the residual
    ``f(q) + f_ext + J_a(q)ᵀ λ`` (paper eq. 9), columns ``1 ... m`` the actuators' columns. The
    tangent ``-dr/dq`` is exact (material, stress and geometric terms, the actuators' load
    stiffness) or, without ``exact``, the material part alone (no load stiffness: positive
    semi-definite whatever the loads). Its blocks go to ``system.values``; with ``into_band``
    its symmetric part goes to the block band ``system.blocks`` instead (the links' added
    straight in, the cables' by the assembly index; the link blocks of ``values`` are then not
    written).

    Parameters
    ----------
    system : EquilibriumRecord
        The terms and buffers.
    positions : (n + 1, 3) ndarray  [m]
        Frame origins.
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations.
    actuation : (m,) ndarray  [Pa, N]
        ``λ``.
    exact : bool
        The exact tangent, else the material part.
    into_band : bool
        Assemble the symmetric block band (the control tick's).

    """
    rhs = system.rhs
    rhs[:, :] = 0.0
    if into_band:
        system.blocks[:, :, :, :] = 0.0
    link_pass(system, positions, rotations, actuation, exact, into_band)
    if system.cable_frames.size > 0:
        cable_pass(system, positions, rotations, actuation)
        if not exact:
            system.values[system.pair_start:] = 0.0
    if system.mesh_columns.size > 0:
        mesh_cavity_pass(system, positions, rotations, actuation)
    external = system.external
    for row in range(rhs.shape[0]):
        rhs[row, 0] += external[row]
    if into_band:
        first = system.pair_start
        scatter_more(system.index[first:], system.values[first:], system.weights[first:],
                     system.blocks.reshape(system.blocks.size))


@numba.njit(cache=True)
def assemble_symmetric(system):
    """Add every block of ``system.values`` into the zeroed block band (½ off the diagonal)."""
    scatter_add(system.index, system.values, system.weights,
                system.blocks.reshape(system.blocks.size))


@numba.njit(cache=True)
def assemble_exact(system):
    """Add every block of ``system.values`` into the zeroed blocks of the exact tangent."""
    exact = system.exact_blocks
    exact[:, :, :, :] = 0.0
    flat = exact.reshape(exact.size)
    values, index = system.values, system.exact_index
    for i in range(index.size):
        flat[index[i]] += values[i]


@numba.njit(cache=True)
def factor_symmetric(system):
    """
    Factor the symmetric block band in place, ``K = L Lᵀ``; return 0 or the failing unknown + 1.

    :func:`~cbha_inverse.core._kernels.block_band.block_cholesky`.
    """
    return block_cholesky(system.blocks[:system.rhs.shape[0] // 6])


@numba.njit(cache=True)
def factor_exact(system):
    """
    Assemble and factor the exact tangent's blocks, ``K = L U``; return 0 or the failing unknown.

    The failing unknown is counted from 1. :func:`assemble_exact`, then
    :func:`~cbha_inverse.core._kernels.block_lu.block_lu` (a non-finite pivot fails it; a
    non-finite entry elsewhere gives a non-finite solve, which the callers refuse).
    """
    assemble_exact(system)
    return block_lu(system.exact_blocks[:system.rhs.shape[0] // 6], system.lu_pivots)
