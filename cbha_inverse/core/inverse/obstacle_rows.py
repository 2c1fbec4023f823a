"""
The obstacle rows of the actuation QP: unilateral constraints on the collision spheres.

At each linearisation, the signed distance ``φ`` of every collision sphere's centre ``p_s``
(:class:`cbha_inverse.core.contact.CollisionSpheres`, radius ``ρ_s``) to every obstacle
(outward normal ``n``) is queried; each (sphere, obstacle) pair whose clearance ``φ(p_s) - ρ_s``
is below the activation distance adds one row

    φ(p_s) + nᵀ (p_s' - p_s) - ρ_s ≥ margin,     p_s' = offset_s + W_sa λ,

``p_s'`` the sphere's centre after the tick in the linear model of the tick (paper eq. 11 for
the centre, a point on its frame like an effector point: the same projection,
:func:`cbha_inverse.core._kernels.tick.project_points_of`, one more block ``W_sa`` of ``W``).
In the actuation ``λ`` a row reads ``G λ + c ≥ 0`` with ``G = nᵀ W_sa`` [m/Pa, m/N] and
``c = φ - ρ_s - margin + nᵀ (offset_s - p_s)`` [m]. The rows are computed inside the compiled
tick, at every linearisation (:func:`cbha_inverse.core._kernels.tick.obstacle_rows_of`, on the
record of :mod:`cbha_inverse.core._kernels.obstacle_rows`); :class:`ObstacleRows` owns that
record and reads it. ``docs/obstacles.md`` describes the rows, their slack, the QP and what a
tick reports.
"""

import math

from cbha_inverse.core._kernels import obstacle_rows as kernels
from cbha_inverse.core._kernels.obstacle_rows import BINDING_TOLERANCE  # noqa: F401 (public)
from cbha_inverse.core._kernels.records import make_record
from cbha_inverse.core.obstacles import check_names, Obstacle, pack_obstacles
import numpy as np

VIOLATION_TOLERANCE = 1e-5
"""A row of a solved QP violated by more than this [m] means the rows cannot all hold: the
tick reads ``'obstacle'``."""


def checked_obstacles(obstacles):
    """
    Return the obstacles as a tuple, each an ``Obstacle`` (finite by construction), names distinct.

    Raises
    ------
    ValueError
        On something that is not an :class:`~cbha_inverse.core.obstacles.Obstacle` or two
        obstacles of one name.

    """
    obstacles = tuple(obstacles)
    for obstacle in obstacles:
        if not isinstance(obstacle, Obstacle):
            raise ValueError(f'obstacles must be Obstacle objects, got {type(obstacle).__name__}')
    return tuple(check_names(obstacles))


def sphere_shares(sphere_frames, effector_frames):
    """
    Return each collision sphere's share of each effector's plant offset (``set_plant_offsets``).

    A sphere on frame ``f`` takes ``f / f_e`` of the offset of the first effector at or beyond
    it (frame ``f_e``), all of the last effector's offset beyond the last effector: the offset
    of the plant from the model grows along the arm from nothing at the base.

    Parameters
    ----------
    sphere_frames : (s,) array_like of int
        The collision spheres' frames (1..n).
    effector_frames : (k,) array_like of int
        The effectors' frames.

    Returns
    -------
    (s, k) ndarray
        ``shifts = shares @ offsets``.

    """
    spheres = np.asarray(sphere_frames, dtype=np.int64).reshape(-1)
    effectors = np.asarray(effector_frames, dtype=np.int64).reshape(-1)
    shares = np.zeros((spheres.size, effectors.size))
    if not effectors.size:
        return shares
    order = np.argsort(effectors, kind='stable')
    for sphere, frame in enumerate(spheres):
        beyond = order[effectors[order] >= frame]
        effector = beyond[0] if beyond.size else order[-1]
        shares[sphere, effector] = min(1.0, frame / max(int(effectors[effector]), 1))
    return shares


def obstacle_rows_record(n_links, n_actuators, obstacles=(), frames=(), radii=(), margin=0.0,
                         activation=0.0, weight=1.0, entering_move=math.inf,
                         entering_rounds=1):
    """
    Return a new obstacle rows record and its arrays by field name.

    Parameters
    ----------
    n_links, n_actuators : int
        ``n``, ``m`` of the solver.
    obstacles : sequence of cbha_inverse.core.obstacles.Obstacle
        The obstacles (``o``; none: a record without rows).
    frames : (s,) array_like of int
        The collision spheres' frames (1..n).
    radii : (s,) array_like  [m]
        Their radii.
    margin, activation : float  [m]
        ``obstacle_margin``, ``obstacle_activation``.
    weight : float
        ``obstacle_weight`` ``ρ``.
    entering_move : float
        Fraction of an actuator's range a solve must move it by for the check of its step.
    entering_rounds : int
        Solves of a tick's QP at most.

    Returns
    -------
    record : cbha_inverse.core._kernels.obstacle_rows.ObstacleRowsRecord
    arrays : dict of str to ndarray

    """
    n, m = int(n_links), int(n_actuators)
    shapes, positions, rotations, sizes = pack_obstacles(obstacles)
    sphere_frames = np.array(frames, dtype=np.int64).reshape(-1)
    s, o = sphere_frames.size, shapes.size
    capacity = s * o
    arrays = {
        'obstacle_shapes': shapes, 'obstacle_positions': positions,
        'obstacle_rotations': rotations, 'obstacle_sizes': sizes,
        'sphere_frames': sphere_frames,
        'sphere_radii': np.array(radii, dtype=float).reshape(-1),
        'sphere_shifts': np.zeros((s, 3)), 'centre': np.zeros(3),
        'forced': np.zeros((s, o), dtype=np.bool_), 'count': np.zeros(1, dtype=np.int64),
        'row_spheres': np.zeros(capacity, dtype=np.int64),
        'row_obstacles': np.zeros(capacity, dtype=np.int64),
        'row_frames': np.zeros(capacity, dtype=np.int64), 'distances': np.zeros(capacity),
        'normals': np.zeros((capacity, 3)), 'matrix': np.zeros((capacity, m)),
        'constant': np.zeros(capacity), 'normal': np.zeros(3), 'closest': np.zeros(3),
        'curvature': np.zeros((3, 3)), 'offsets': np.zeros((capacity, 3)),
        'levers': np.zeros((capacity, 3)), 'columns': np.zeros(6 * n * 3 * capacity),
        'starts': np.zeros(3 * capacity, dtype=np.int64), 'w_pa': np.zeros((3 * capacity, m)),
        'w_aa': np.zeros((m, m)), 'free_centres': np.zeros(3 * capacity),
        'moved': np.zeros((3 * capacity, m + 1)), 'scaled_matrix': np.zeros((capacity, m)),
        'values': np.zeros(capacity), 'row_on': np.zeros(capacity, dtype=np.bool_),
        'penalised_hessian': np.zeros((m, m)), 'penalised_gradient': np.zeros(m),
        'stepped_positions': np.zeros((n + 1, 3)), 'stepped_rotations': np.zeros((n + 1, 3, 3)),
        'targets_inside': np.zeros(o, dtype=np.bool_),
        'violation': np.full(1, math.nan), 'binds': np.zeros(1, dtype=np.bool_)}
    record = make_record(kernels.ObstacleRowsRecord, kernels.new_obstacle_rows_record,
                         margin=float(margin), activation=float(activation),
                         weight=float(weight), entering_move=float(entering_move),
                         entering_rounds=int(entering_rounds), **arrays)
    return record, arrays


class ObstacleRows:
    """
    The obstacle rows of one solver's linearisation (module docstring).

    Builds the record of the obstacles, the spheres and the rows and attaches it to the tick
    data: the compiled tick then computes the rows at every linearisation and solves its QP
    with them. This object reads them.

    Parameters
    ----------
    spheres : cbha_inverse.core.contact.CollisionSpheres
        The robot's collision spheres.
    obstacles : sequence of cbha_inverse.core.obstacles.Obstacle
        The obstacles (names distinct).
    margin : float  [m]
        Clearance the rows keep (>= 0).
    activation : float  [m]
        A pair adds a row when its clearance is below ``margin + activation``.
    tick_data : cbha_inverse.core.inverse.tick_data.TickData
        The solver's tick buffers (the linearisation the rows project on).
    weight : float
        ``ρ`` of the rows' slack (``obstacle_weight``).
    entering_move : float
        A solve moving an actuator by more than this fraction of its range checks its step for
        spheres entering an obstacle without a row.
    entering_rounds : int
        Solves of a tick's QP at most.

    Attributes
    ----------
    record : cbha_inverse.core._kernels.obstacle_rows.ObstacleRowsRecord
        The record (``tick_data.record.rows``).
    count : int
        Rows of the current linearisation.
    matrix : (count, m) ndarray  [m/Pa, m/N]
        ``G``.
    constant : (count,) ndarray  [m]
        ``c``.
    names : tuple of str
        The obstacle of each row.
    frames : (count,) int ndarray
        The sphere's frame of each row.

    """

    def __init__(self, spheres, obstacles, margin, activation, tick_data, weight=1e6,
                 entering_move=math.inf, entering_rounds=1):
        """Check the parameters, build the record and attach it to the tick data."""
        for name, value in (('obstacle_margin', margin), ('obstacle_activation', activation)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0.0):
                raise ValueError(f'{name} must be a finite distance >= 0 [m], got {value!r}')
        n_links = tick_data.positions.shape[0] - 1
        if spheres.frames.size and spheres.frames.max() > n_links:
            raise ValueError(f'collision spheres: frame {spheres.frames.max()} beyond the chain '
                             f'(frames 1..{n_links})')
        self.spheres = spheres
        self.obstacles = checked_obstacles(obstacles)
        self.margin, self.activation = float(margin), float(activation)
        self.record, self._arrays = obstacle_rows_record(
            n_links, tick_data.actuation.size, self.obstacles, spheres.frames, spheres.radii,
            margin, activation, weight, entering_move, entering_rounds)
        self._data = tick_data
        tick_data.attach_rows(self.record)
        self._names = tuple(obstacle.name for obstacle in self.obstacles)
        self._last_targets, self._last_warnings = b'', ()
        self.clear()

    def clear(self):
        """Drop the rows and the pairs :meth:`add_entering` added (no linearisation yet)."""
        self._arrays['count'][0] = 0
        self._arrays['forced'][:] = False
        self._arrays['violation'][0] = math.nan
        self._arrays['binds'][0] = False

    @property
    def count(self):
        """Return the number of rows of the current linearisation."""
        return int(self._arrays['count'][0])

    @property
    def matrix(self):
        """Return ``G`` (count, m) [m/Pa, m/N] (a view of the record)."""
        return self._arrays['matrix'][:self.count]

    @property
    def constant(self):
        """Return ``c`` (count,) [m] (a view of the record)."""
        return self._arrays['constant'][:self.count]

    @property
    def names(self):
        """Return the obstacle of each row (tuple of str)."""
        return tuple(self._names[o] for o in self._arrays['row_obstacles'][:self.count])

    @property
    def frames(self):
        """Return the sphere's frame of each row, (count,) int ndarray."""
        return self._arrays['row_frames'][:self.count].copy()

    def set_shifts(self, shifts):
        """
        Move every sphere's centre by the plant's estimated displacement for the distance query.

        The rows then keep the plant's spheres ``obstacle_margin`` clear where the closed loop
        measures the plant away from the model (:meth:`InverseSolver.set_plant_offsets
        <cbha_inverse.core.inverse.solver.InverseSolver.set_plant_offsets>`); the next
        linearisation uses them.

        Parameters
        ----------
        shifts : (s, 3) ndarray  [m]
            Per collision sphere, finite.

        """
        self._arrays['sphere_shifts'][:] = shifts

    def outcome(self):
        """
        Return the rows of the last compiled solve, their largest violation [m], whether one binds.

        Returns
        -------
        tuple of (int, float, bool)

        """
        return (self.count, float(self._arrays['violation'][0]), bool(self._arrays['binds'][0]))

    def warm_up(self):
        """Compile (or load) :meth:`add_entering` and :meth:`inside`."""
        self._entering()
        self._inside_of()

    def _inside_of(self):
        """Return the compiled :func:`~cbha_inverse.core._kernels.tick.targets_inside_of`."""
        data = self._data
        return data.entry('targets_inside_of', (data.effector_positions, data.record))

    def _entering(self):
        """Return the compiled :func:`~cbha_inverse.core._kernels.tick.add_entering_rows`."""
        data = self._data
        return data.entry('add_entering_rows', (data.record, data.actuation))

    def add_entering(self, actuation):
        """
        Add the pairs the step to ``actuation`` would bring within the margin without a row.

        A pair beyond the activation distance at the linearisation has no row, but a long step
        may still carry its sphere into the obstacle: given the actuation of a solve, every pair
        without a row whose clearance after the linearisation's step to it is below the margin
        is added to the rows, at the same linearisation
        (:func:`cbha_inverse.core._kernels.tick.add_entering_rows`): the caller solves again.

        Parameters
        ----------
        actuation : (m,) ndarray  [Pa, N]
            The actuation of the solve.

        Returns
        -------
        bool
            Whether a pair was added.

        """
        actuation = np.ascontiguousarray(actuation, dtype=float)
        return bool(self._entering()(self._data.record, actuation))

    def clearances(self, actuation):
        """
        Return each row's predicted clearance above the margin at ``actuation``, ``G λ + c`` [m].

        Parameters
        ----------
        actuation : (m,) ndarray  [Pa, N]
            The actuation ``λ``.

        Returns
        -------
        (count,) ndarray  [m]

        """
        return self.matrix @ actuation + self.constant

    def inside_warnings(self, targets):
        """
        Return a tick's warnings for targets inside obstacles (:meth:`inside`).

        The same targets as the last call's (their bytes) give the same warnings without a query.

        Parameters
        ----------
        targets : (k, 3) ndarray  [m]
            Effector targets.

        Returns
        -------
        tuple of str

        """
        key = np.ascontiguousarray(targets, dtype=float).tobytes()
        if key != self._last_targets:
            self._last_targets = key
            self._last_warnings = tuple(
                f'target inside obstacle {name!r}: the obstacle rows hold the arm out'
                for name in self.inside(targets))
        return self._last_warnings

    def inside(self, targets):
        """
        Return the names of the obstacles some target lies inside of (``φ < 0``).

        The compiled query of every target against every obstacle
        (:func:`cbha_inverse.core._kernels.obstacle_rows.targets_inside_obstacles`).

        Parameters
        ----------
        targets : (k, 3) array_like  [m]
            Effector targets.

        Returns
        -------
        tuple of str

        Raises
        ------
        ValueError
            If ``targets`` is not a finite (k, 3) array.

        """
        targets = np.array(targets, dtype=float, order='C')
        if targets.ndim != 2 or targets.shape[1] != 3 or not np.all(np.isfinite(targets)):
            raise ValueError(f'targets must be finite (k, 3), got shape {targets.shape}')
        if not self._inside_of()(targets, self._data.record):
            return ()
        return tuple(name for name, inside in zip(self._names, self._arrays['targets_inside'])
                     if inside)
