"""
The obstacle rows of the actuation QP as compiled code over one record (``docs/obstacles.md``).

At each linearisation the signed distance ``φ`` of every collision sphere's centre ``p_s``
(radius ``ρ_s``, a frame origin, moved by the sphere's ``sphere_shifts``) to every obstacle
(:func:`cbha_inverse.core._kernels.obstacles.signed_distance_at`, outward normal ``n``) is
queried (:func:`select_pairs_of`); each (sphere, obstacle) pair whose clearance ``φ - ρ_s`` is
below ``margin + activation``, or that :func:`add_entering_pairs` forced, adds one row

    φ(p_s) + nᵀ (p_s' - p_s) - ρ_s ≥ margin,     p_s' = free_s + W_sa λ,

``p_s'`` the centre after the tick in the tick's linear model (paper eq. 11 for the centre:
:func:`cbha_inverse.core._kernels.tick.project_points_of` writes ``W_sa`` and ``free_s``). In
the actuation ``λ`` a row reads ``G λ + c ≥ 0`` (:func:`rows_from_projection_of`):

    G = nᵀ W_sa  [m/Pa, m/N],     c = φ - ρ_s - margin + nᵀ (free_s - p_s)  [m].

The QP takes each row with a slack (:func:`cbha_inverse.core._kernels.qp.rows_qp_into`);
:func:`row_outcome_of` reports the rows' largest violation and whether one binds. The record's
fields are :data:`OBSTACLE_ROW_FIELDS` (owned by
:class:`cbha_inverse.core.inverse.obstacle_rows.ObstacleRows`, nested in the tick's record as
its ``rows``).
"""

from cbha_inverse.core._kernels.obstacles import signed_distance_at
from cbha_inverse.core._kernels.records import define_record, Field, Record, RecordType
import numba
from numba.experimental import structref
import numpy as np

F8, I8 = np.float64, np.int64

BINDING_TOLERANCE = 1e-6
"""A row satisfied within this [m] binds: it holds the arm against the obstacle."""

OBSTACLE_ROW_FIELDS = (
    # the obstacles (cbha_inverse.core.obstacles.pack_obstacles)
    # (read-only: the query takes them as it takes an Obstacle's own read-only arrays)
    Field('obstacle_shapes', I8, 1, '(o,) shape code of every obstacle (obstacles.SHAPES)',
          read_only=True),
    Field('obstacle_positions', F8, 2, "(o, 3) origin of every obstacle's frame [m]",
          read_only=True),
    Field('obstacle_rotations', F8, 3, "(o, 3, 3) axes of every obstacle's frame",
          read_only=True),
    Field('obstacle_sizes', F8, 2, '(o, 3) sizes of every obstacle (signed_distance_at) [m]',
          read_only=True),
    # the collision spheres and the rows' parameters
    Field('sphere_frames', I8, 1, '(s,) frame of every collision sphere (1..n)',
          read_only=True),
    Field('sphere_radii', F8, 1, '(s,) radius ρ_s of every collision sphere [m]',
          read_only=True),
    Field('sphere_shifts', F8, 2, "(s, 3) the plant's estimated displacement of every "
          "sphere's centre from the model's, added before the distance query [m]"),
    Field('margin', float, 0, 'the clearance the rows keep [m]'),
    Field('activation', float, 0, 'a pair adds a row below margin + activation of clearance '
          '[m]'),
    Field('weight', float, 0, "ρ: a row's slack s costs ½ ρ s² / ν"),
    Field('entering_move', float, 0, 'a solve moving an actuator by more than this fraction '
          'of its range checks its step for entering pairs'),
    Field('entering_rounds', int, 0, "solves of a tick's QP at most (add_entering_pairs)"),
    Field('forced', np.bool_, 2, '(s, o) pairs add_entering_pairs added: a row whatever their '
          'clearance'),
    # the rows of the linearisation: capacity c = s o
    Field('count', I8, 1, '(1,) rows of the current linearisation'),
    Field('row_spheres', I8, 1, '(c,) the sphere of every row'),
    Field('row_obstacles', I8, 1, '(c,) the obstacle of every row'),
    Field('row_frames', I8, 1, "(c,) the sphere's frame of every row"),
    Field('distances', F8, 1, '(c,) φ of every row at the linearisation [m]'),
    Field('normals', F8, 2, '(c, 3) n of every row'),
    Field('matrix', F8, 2, '(c, m) G [m/Pa, m/N]'),
    Field('constant', F8, 1, '(c,) c [m]'),
    # the distance query's workspace
    Field('centre', F8, 1, '(3,) the shifted centre of one query [m]'),
    Field('normal', F8, 1, '(3,) the outward normal of one query'),
    Field('closest', F8, 1, '(3,) the closest surface point of one query [m]'),
    Field('curvature', F8, 2, '(3, 3) the Hessian of one query [1/m]'),
    # the projection of the rows' centres (project_points_of)
    Field('offsets', F8, 2, '(c, 3) the centres in their frames: zero (frame origins) [m]'),
    Field('levers', F8, 2, '(c, 3) workspace: R_f o [m]'),
    Field('columns', F8, 1, '(6n 3c,) workspace: J_pᵀ of r rows, then L⁻¹ J_pᵀ, a (6n, 3r) '
          'C-ordered array (column_block_of)'),
    Field('starts', I8, 1, '(3c,) workspace: first nonzero row of each column'),
    Field('w_pa', F8, 2, '(3c, m) W_sa of every row [m/Pa, m/N]'),
    Field('w_aa', F8, 2, '(m, m) workspace: W_aa'),
    Field('free_centres', F8, 1, '(3c,) free_s of every row: the centre is free_s + W_sa λ [m]'),
    Field('moved', F8, 2, '(3c, m + 1) workspace: J_p K⁻¹ [r, J_aᵀ]'),
    # the QP with the rows (qp.rows_qp_into)
    Field('scaled_matrix', F8, 2, '(c, m) A = G σ [m]'),
    Field('values', F8, 1, '(c,) A x + b of the solution [m]'),
    Field('row_on', np.bool_, 1, "(c,) rows whose slack's penalty is on"),
    Field('penalised_hessian', F8, 2, '(m, m) workspace: H_S'),
    Field('penalised_gradient', F8, 1, '(m,) workspace: g_S'),
    # the check of a long step (add_entering_pairs)
    Field('stepped_positions', F8, 2, '(n + 1, 3) workspace: frame origins after a step [m]'),
    Field('stepped_rotations', F8, 3, '(n + 1, 3, 3) workspace: frame rotations after it'),
    # the check of the targets (targets_inside_obstacles)
    Field('targets_inside', np.bool_, 1, '(o,) the obstacles some target lies inside of'),
    # the outcome (row_outcome_of)
    Field('violation', F8, 1, "(1,) the rows' largest slack at the solution [m] (NaN: no "
          'row)'),
    Field('binds', np.bool_, 1, '(1,) whether a row holds within BINDING_TOLERANCE'),
)
"""The fields of :class:`ObstacleRowsRecord`."""


@structref.register
class ObstacleRowsRecordType(RecordType):
    """The numba type of :class:`ObstacleRowsRecord`."""


class ObstacleRowsRecord(Record):
    """The obstacles, spheres and rows of one solver (:data:`OBSTACLE_ROW_FIELDS`)."""

    __slots__ = ()


define_record(ObstacleRowsRecord, ObstacleRowsRecordType, OBSTACLE_ROW_FIELDS)


@numba.njit(cache=True)
def new_obstacle_rows_record(*values):
    """Build an :class:`ObstacleRowsRecord` (fields in declaration order)."""
    return ObstacleRowsRecord(*values)


@numba.njit(cache=True)
def column_block_of(rows, size):
    """
    Return the ``columns`` workspace as the (size, 3r) C-ordered array of the ``r`` rows.

    ``size`` = 6n; a C-ordered array whatever ``r``, as the effectors' columns are (one
    compiled copy of the projection for both).
    """
    points = 3 * rows.count[0]
    return rows.columns[:size * points].reshape((size, points))


@numba.njit(cache=True)
def pair_distance_of(rows, sphere, obstacle, positions):
    """
    Return the signed distance [m] of a sphere's centre to an obstacle; its normal in ``normal``.

    The centre is the origin of the sphere's frame in ``positions`` (n + 1, 3) [m] plus the
    sphere's ``sphere_shifts`` (the plant's sphere where the closed loop measures the plant
    away from the model, ``docs/obstacles.md``; zero in open loop).
    """
    origin = positions[rows.sphere_frames[sphere]]
    shift, centre = rows.sphere_shifts[sphere], rows.centre
    for i in range(3):
        centre[i] = origin[i] + shift[i]
    return signed_distance_at(rows.obstacle_shapes[obstacle], rows.obstacle_positions[obstacle],
                              rows.obstacle_rotations[obstacle], rows.obstacle_sizes[obstacle],
                              centre, rows.normal, rows.closest, rows.curvature)


@numba.njit(cache=True)
def select_pairs_of(rows, positions):
    """
    Write the pairs of the rows at the frames ``positions`` (n + 1, 3) [m]; return their count.

    Every sphere against every obstacle: a pair whose clearance ``φ - ρ_s`` is below
    ``margin + activation``, or a ``forced`` one, is a row (``row_spheres``, ``row_obstacles``,
    ``row_frames``, ``distances``, ``normals``); sphere by sphere, obstacle by obstacle.
    """
    reach = rows.margin + rows.activation
    count = 0
    for sphere in range(rows.sphere_frames.size):
        for obstacle in range(rows.obstacle_shapes.size):
            distance = pair_distance_of(rows, sphere, obstacle, positions)
            if distance - rows.sphere_radii[sphere] < reach or rows.forced[sphere, obstacle]:
                rows.row_spheres[count] = sphere
                rows.row_obstacles[count] = obstacle
                rows.row_frames[count] = rows.sphere_frames[sphere]
                rows.distances[count] = distance
                for i in range(3):
                    rows.normals[count, i] = rows.normal[i]
                count += 1
    rows.count[0] = count
    return count


@numba.njit(cache=True)
def rows_from_projection_of(rows, positions):
    """
    Write ``G`` and ``c`` of the selected rows from their centres' projection (module docstring).

    ``G_i = n_iᵀ W_sa,i`` and ``c_i = φ_i - ρ_s - margin + n_iᵀ (free_s,i - p_s,i)``, with
    ``W_sa`` and ``free_s`` in ``w_pa`` and ``free_centres`` (three rows per row) and ``p_s``
    the frame origins ``positions`` (n + 1, 3) [m] of the linearisation.
    """
    m = rows.matrix.shape[1]
    for row in range(rows.count[0]):
        constant = (rows.distances[row] - rows.sphere_radii[rows.row_spheres[row]]
                    - rows.margin)
        centre = positions[rows.row_frames[row]]
        for i in range(3):
            constant += rows.normals[row, i] * (rows.free_centres[3 * row + i] - centre[i])
        rows.constant[row] = constant
        for j in range(m):
            total = 0.0
            for i in range(3):
                total += rows.normals[row, i] * rows.w_pa[3 * row + i, j]
            rows.matrix[row, j] = total


@numba.njit(cache=True)
def add_entering_pairs(rows, positions):
    """
    Force the pairs without a row that the frames ``positions`` bring within the margin.

    A pair beyond the activation distance at the linearisation has no row, but a long step may
    still carry its sphere into the obstacle: given the frames the step would reach
    (n + 1, 3) [m], every pair without a row whose clearance there is below ``margin`` is
    marked ``forced`` (a row at the next selection). Returns whether a pair was added.
    """
    added = False
    for sphere in range(rows.sphere_frames.size):
        for obstacle in range(rows.obstacle_shapes.size):
            if rows.forced[sphere, obstacle] or has_row(rows, sphere, obstacle):
                continue
            distance = pair_distance_of(rows, sphere, obstacle, positions)
            if distance - rows.sphere_radii[sphere] < rows.margin:
                rows.forced[sphere, obstacle] = True
                added = True
    return added


@numba.njit(cache=True)
def targets_inside_obstacles(rows, targets):
    """
    Mark the obstacles some target (k, 3) [m] lies inside of (``φ < 0``); return their count.

    ``targets_inside`` receives the marks: a target inside an obstacle is projected out by the
    rows, and the tick says so (``docs/obstacles.md``).
    """
    count = 0
    for obstacle in range(rows.obstacle_shapes.size):
        inside = False
        for target in range(targets.shape[0]):
            distance = signed_distance_at(
                rows.obstacle_shapes[obstacle], rows.obstacle_positions[obstacle],
                rows.obstacle_rotations[obstacle], rows.obstacle_sizes[obstacle],
                targets[target], rows.normal, rows.closest, rows.curvature)
            inside = inside or distance < 0.0
        rows.targets_inside[obstacle] = inside
        count += inside
    return count


@numba.njit(cache=True)
def has_row(rows, sphere, obstacle):
    """Return whether the pair (sphere, obstacle) has a row."""
    for row in range(rows.count[0]):
        if rows.row_spheres[row] == sphere and rows.row_obstacles[row] == obstacle:
            return True
    return False


@numba.njit(cache=True)
def scale_rows_of(rows, scale, x_previous):
    """
    Write ``A = G σ`` and start each row's state from its sign at ``x_previous``.

    ``scale`` ``σ`` (m,), ``x_previous`` (m,) the QP's ``λ_prev / σ``: a row is on (its slack's
    penalty active) where ``A x_prev + c < 0``.
    """
    m = scale.size
    for row in range(rows.count[0]):
        value = rows.constant[row]
        for j in range(m):
            rows.scaled_matrix[row, j] = rows.matrix[row, j] * scale[j]
            value += rows.scaled_matrix[row, j] * x_previous[j]
        rows.row_on[row] = value < 0.0


@numba.njit(cache=True)
def row_outcome_of(rows, x, actuation):
    """
    Write the rows' largest slack at ``x`` and whether one binds at ``actuation``.

    ``violation``: ``max_i max(0, -(A_i x + c_i))`` [m] (``x`` the QP's solution, (m,));
    ``binds``: some ``G_i λ + c_i < BINDING_TOLERANCE`` at the actuation ``λ`` (m,) [Pa, N]
    (``x`` within the bounds). No row: NaN and False.
    """
    largest, binds = 0.0, False
    count = rows.count[0]
    for row in range(count):
        value, clearance = rows.constant[row], rows.constant[row]
        for j in range(x.size):
            value += rows.scaled_matrix[row, j] * x[j]
            clearance += rows.matrix[row, j] * actuation[j]
        rows.values[row] = value
        largest = max(largest, -value)
        binds = binds or clearance < BINDING_TOLERANCE
    rows.violation[0] = largest if count else np.nan
    rows.binds[0] = binds
