"""
The obstacle rows of the actuation QP: unilateral constraints on the collision spheres.

At each linearisation, the signed distance ``φ`` of every collision sphere's centre ``p_s``
(:class:`cbha_inverse.core.contact.CollisionSpheres`, radius ``ρ_s``) to every obstacle
(:meth:`cbha_inverse.core.obstacles.Obstacle.signed_distance`, outward normal ``n``) is queried;
each (sphere, obstacle) pair whose clearance ``φ(p_s) - ρ_s`` is below the activation distance
adds one row

    φ(p_s) + nᵀ (p_s' - p_s) - ρ_s ≥ margin,     p_s' = offset_s + W_sa λ,

``p_s'`` the sphere's centre after the tick in the linear model of the tick (paper eq. 11 for
the centre, a point on its frame like an effector point: the same projection,
:func:`cbha_inverse.core._kernels.tick.project_points_of`, one more block ``W_sa`` of ``W``).
In the actuation ``λ`` a row reads ``G λ + c ≥ 0`` with ``G = nᵀ W_sa`` [m/Pa, m/N] and
``c = φ - ρ_s - margin + nᵀ (offset_s - p_s)`` [m]. ``docs/obstacles.md`` describes the rows,
their slack and what a tick reports.
"""

import math

from cbha_inverse.core.obstacles import check_names, Obstacle
import numpy as np

VIOLATION_TOLERANCE = 1e-5
"""A row of a solved QP violated by more than this [m] means the rows cannot all hold: the
tick reads ``'obstacle'``."""
BINDING_TOLERANCE = 1e-6
"""A row satisfied within this [m] binds: it holds the arm against the obstacle."""


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


class ObstacleRows:
    """
    The obstacle rows of one solver's linearisation (module docstring).

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

    Attributes
    ----------
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

    def __init__(self, spheres, obstacles, margin, activation, tick_data):
        """Check the parameters and keep the parts."""
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
        self._data = tick_data
        self._project = None
        self._forced = set()
        self._last_targets, self._last_warnings = None, ()
        self.clear()

    def clear(self):
        """Drop the rows and the pairs :meth:`add_entering` added (no linearisation yet)."""
        self._forced = set()
        m = self._data.actuation.size
        self.count = 0
        self.matrix, self.constant = np.zeros((0, m)), np.zeros(0)
        self.names, self.frames = (), np.zeros(0, dtype=np.int64)

    def linearise(self):
        """
        Build the rows at the tick data's linearisation (its frames, solves and ``λ_prev``).

        The pairs within the activation distance, and those :meth:`add_entering` added since
        the last :meth:`clear`.

        Returns
        -------
        int
            The number of rows.

        """
        data = self._data
        centres = self.spheres.centres(data.positions)
        radii = self.spheres.radii
        reach = self.margin + self.activation
        sphere, names, distance, normal = [], [], [], []
        for index, obstacle in enumerate(self.obstacles):
            near = np.flatnonzero(obstacle.near(centres, radii + reach))
            forced = [s for o, s in self._forced if o == index]
            if forced:
                near = np.union1d(near, forced)
            if not near.size:
                continue
            query = obstacle.signed_distance(centres[near])
            within = query.distance - radii[near] < reach
            if forced:
                within |= np.isin(near, forced)
            active = np.flatnonzero(within)
            sphere.append(near[active])
            names += [obstacle.name] * active.size
            distance.append(query.distance[active])
            normal.append(query.normal[active])
        if not names:
            self.clear()
            return 0
        sphere = np.concatenate(sphere)
        normal, distance = np.concatenate(normal), np.concatenate(distance)
        frames = np.ascontiguousarray(self.spheres.frames[sphere], dtype=np.int64)
        w_pa, offset = self._project_centres(frames)
        rows = sphere.size
        self.matrix = np.einsum('si,sij->sj', normal, w_pa.reshape(rows, 3, -1))
        moved = offset.reshape(rows, 3) - centres[sphere]
        self.constant = (distance - radii[sphere] - self.margin
                         + np.einsum('si,si->s', normal, moved))
        self.count, self.names, self.frames = rows, tuple(names), frames
        return rows

    def warm_up(self):
        """Compile (or load) the projection of the centres: project the first sphere's."""
        self._project_centres(np.ascontiguousarray(self.spheres.frames[:1], dtype=np.int64))

    def _project_centres(self, frames):
        """Return ``W_sa`` (3s, m) and the free centres (3s,) of spheres on ``frames``."""
        data = self._data
        s, m = frames.size, data.actuation.size
        size = data.solved.shape[0]
        offsets, levers = np.zeros((s, 3)), np.zeros((s, 3))
        columns, starts = np.zeros((size, 3 * s)), np.zeros(3 * s, dtype=np.int64)
        w_pa, w_aa = np.zeros((3 * s, m)), np.zeros((m, m))
        offset, moved = np.zeros(3 * s), np.zeros((3 * s, m + 1))
        arguments = (data.record, frames, offsets, levers, columns, starts, w_pa, w_aa, offset,
                     moved)
        if self._project is None:
            self._project = data.entry('project_points_of', arguments)
        self._project(*arguments)
        return w_pa, offset

    def add_entering(self, positions):
        """
        Add the pairs a step would bring within the margin without a row, and relinearise.

        A pair beyond the activation distance at the linearisation has no row, but a long step
        may still carry its sphere into the obstacle. Given the frames the step would reach,
        every pair without a row whose clearance there is below the margin is added to the
        rows (:meth:`linearise`, at the same linearisation): the caller solves again.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins after the step.

        Returns
        -------
        bool
            Whether a pair was added.

        """
        centres, radii = self.spheres.centres(positions), self.spheres.radii
        rows = set(zip(self.names, self.frames.tolist()))
        added = False
        for index, obstacle in enumerate(self.obstacles):
            near = np.flatnonzero(obstacle.near(centres, radii + self.margin))
            if not near.size:
                continue
            clearance = obstacle.signed_distance(centres[near]).distance - radii[near]
            for sphere in near[clearance < self.margin]:
                frame = int(self.spheres.frames[sphere])
                if (obstacle.name, frame) not in rows and (index, sphere) not in self._forced:
                    self._forced.add((index, int(sphere)))
                    added = True
        if added:
            self.linearise()
        return added

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

        The same targets as the last call's give the same warnings without a query.

        Parameters
        ----------
        targets : (k, 3) ndarray  [m]
            Effector targets.

        Returns
        -------
        tuple of str

        """
        if self._last_targets is None or not np.array_equal(targets, self._last_targets):
            self._last_targets = targets.copy()
            self._last_warnings = tuple(
                f'target inside obstacle {name!r}: the obstacle rows hold the arm out'
                for name in self.inside(targets))
        return self._last_warnings

    def inside(self, targets):
        """
        Return the names of the obstacles some target lies inside of (``φ < 0``).

        Parameters
        ----------
        targets : (k, 3) ndarray  [m]
            Effector targets.

        Returns
        -------
        tuple of str

        """
        inside = []
        for obstacle in self.obstacles:
            near = obstacle.near(targets, 0.0)
            if near.any() and np.any(obstacle.signed_distance(targets[near]).distance < 0.0):
                inside.append(obstacle.name)
        return tuple(inside)
