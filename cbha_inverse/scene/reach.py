"""
The reachable set of a scene: where an effector goes over the admissible actuations.

The workspace centre of a scene file (``{actuation_fraction: f}``: every actuator at ``f`` of
its range) is not the centre of what the robot reaches: under gravity, and with tendons that
cannot push, part of a circle around it may lie out of reach. :func:`sample_reachable_set`
samples the reach by forward solves and returns its box, a centre and, in each principal plane,
the largest circle around that centre inside the convex hull of the samples. ``cbha_scene
check`` prints it; ``workspace_center: reachable_center`` in a scene file uses its centre.
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError
from scipy.stats import qmc

PLANES = {'xy': (0, 1), 'yz': (1, 2), 'xz': (0, 2)}
"""The principal planes and their two axes (0 = x, 1 = y, 2 = z of the scene's base frame)."""

DEFAULT_SAMPLES = 300
"""Admissible actuations sampled by default (0.1 to 0.3 s on the shipped scenes)."""

MIN_SAMPLES = 10
"""The fewest samples :func:`sample_reachable_set` accepts (see :func:`fewest_samples`)."""

SINGLE_FRACTIONS = (1.0, 0.5, 0.25, 0.75)
"""Fractions of its range at which each actuator is sampled alone (the others at lower)."""

DIAGONAL_FRACTIONS = (0.25, 0.5, 0.75)
"""Fractions of their ranges at which every actuator is sampled together."""


@dataclass(frozen=True, eq=False)
class ReachableSet:
    """
    A sampled reachable set of one effector (:func:`sample_reachable_set`).

    Attributes
    ----------
    effector : str
        The effector whose positions were sampled.
    actuations : (n, m) ndarray  [N or Pa]
        The sampled actuations whose forward solve converged, scene actuator order.
    points : (n, 3) ndarray  [m]
        The effector at each of them, in the scene's base frame.
    failed : int
        Sampled actuations whose forward solve did not converge (left out of ``points``).
    box_min, box_max : (3,) ndarray  [m]
        The axis-aligned box of ``points``.
    center : (3,) ndarray  [m]
        The reachable centre, one of ``points`` (see :func:`sample_reachable_set`).
    radii : dict
        ``plane -> radius [m]`` for ``'xy'``, ``'yz'`` and ``'xz'``: the largest circle around
        ``center`` in that plane (through ``center``) inside :attr:`halfspaces` (0 when the
        centre lies outside or the reach is flat across that plane).
    widest_plane : str or None
        The plane whose circle chose ``center`` (None: no hull, ``center`` is the box middle).
    halfspaces : (f, 4) ndarray
        The hull as half-spaces ``[n, d]``, inside where ``n . p + d <= 0`` (unit outward
        normals ``n``, offsets ``d`` [m]): the facets of the 3-D convex hull of ``points``, or,
        for a flat reach, the edges of each plane's projected hull extruded along its normal.
    flat_planes : tuple of str
        The planes whose radius is 0 because the reach is flat there (a flat reach only).
    rotations : (n, 3, 3) ndarray
        The effector's frame rotation at each of ``points`` (its orientation's reach).

    """

    effector: str
    actuations: np.ndarray
    points: np.ndarray
    failed: int
    box_min: np.ndarray
    box_max: np.ndarray
    center: np.ndarray
    radii: dict
    widest_plane: str | None
    halfspaces: np.ndarray
    flat_planes: tuple
    rotations: np.ndarray = None

    def radii_around(self, point):
        """
        Return the largest circle in each principal plane through ``point`` inside the hull.

        Parameters
        ----------
        point : (3,) array_like  [m]
            A centre (e.g. the scene's workspace centre).

        Returns
        -------
        dict
            ``plane -> radius [m]`` for ``'xy'``, ``'yz'``, ``'xz'`` (0 outside the hull).

        """
        p = np.asarray(point, dtype=float).reshape(-1)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f'point must be 3 finite coordinates, got {point!r}')
        return _radii(self.halfspaces, self.flat_planes, p)

    def outside_distance(self, points):
        """
        Return how far points lie beyond the hull: the largest signed distance to a facet.

        ``max_f (n_f . p + d_f)`` over the half-spaces: <= 0 inside, > 0 outside, a lower
        bound of the distance to the hull (exact where the nearest hull point lies inside a
        facet).

        Parameters
        ----------
        points : (n, 3) array_like  [m]
            The points, in the scene's base frame.

        Returns
        -------
        (n,) ndarray  [m]
            0 for every point when the set has no half-spaces.

        """
        points = np.asarray(points, dtype=float)
        if points.ndim != 2 or points.shape[1] != 3:
            raise ValueError(f'points must have shape (n, 3), got {points.shape}')
        if not len(self.halfspaces):
            return np.zeros(len(points))
        return np.max(points @ self.halfspaces[:, :3].T + self.halfspaces[:, 3], axis=1)


def sample_reachable_set(scene, samples=DEFAULT_SAMPLES, *, effector=-1, seed=0):
    """
    Sample where an effector of a scene goes over its admissible actuations.

    The samples lie inside the bounds ``[lower, upper]`` (their corners are not needed): the
    lower bounds, each actuator alone at its upper bound and at 1/2, 1/4 and 3/4 of its range,
    every actuator at 1/4, 1/2 and 3/4 of its range together, then a scrambled Halton sequence
    (seeded: the result is deterministic), every second point of it stretched toward the bounds
    (each fraction ``u`` of a range becomes ``clip(2 u - 1/2, 0, 1)``: a quarter of them at
    either bound, where the reach's boundary lies). Each is solved forward (``scene.forward(...,
    check_warnings=False)``) in nearest-neighbour order, warm-started from the previous
    converged sample (cold again when that fails); a solve that does not converge is left out
    and counted in ``failed``.

    *Inside* is the 3-D convex hull of the sampled points, cut by the circle's plane through
    the centre: a circle of the reported radius, in that plane and at the centre's third
    coordinate (what a ``plane: yz`` trajectory asks for), has every point a convex
    combination of reached positions. Not the hull of the samples projected onto the plane:
    that ignores the third coordinate (a trunk's tip moves back along its axis as it bends,
    so a wide y-z circle at the rest's x is out of reach although its y and z are not). A flat
    reach (no volume, e.g. cables in one plane without gravity) uses each plane's projected
    hull instead, and a plane across which it is flat gets radius 0.

    The centre is a sampled point, not the middle of the box: gravity and tendons that cannot
    push move the room for circles away from that middle, and a convex hull fills the holes of
    a reach that is not convex (a trunk reaches far back along its axis only when bent, so the
    hull's widest cut, well behind the rest, surrounds positions it cannot reach). Of the
    sampled points, each reached, it is the one around which the largest circle fits in the
    widest plane (the principal plane holding the largest such circle: for a trunk along x the
    y-z plane, where trajectories are drawn); among equal ones, the one with the larger
    smaller circle in the two other planes, then the one nearest the box middle. Around it no
    circle in the widest plane is larger than the reported radius; about another point a
    larger one may fit.

    The hull still over-estimates a reach with dents, and the samples' hull lies inside the
    true reach where that is convex (a finer sample widens it). Read a radius as an estimate,
    not a guarantee: plan trajectories at least 20 % smaller (more on a robot whose model is
    not yet calibrated) and watch the tracking and the saturated actuators.

    Parameters
    ----------
    scene : cbha_inverse.scene.Scene
        The scene (its model, actuators, bounds and gravity).
    samples : int
        Actuations sampled (at least :func:`fewest_samples` of the actuators).
    effector : int or str
        The effector sampled, by index or name (default the last one, the tip).
    seed : int
        Seed of the Halton scrambling (>= 0).

    Returns
    -------
    ReachableSet

    Raises
    ------
    ValueError
        If ``samples``, ``effector`` or ``seed`` is not valid.
    RuntimeError
        If fewer than 3 forward solves converge.

    """
    names = tuple(scene.effector_names)
    index = _effector_index(effector, names)
    low = np.asarray(scene.lower_bounds, dtype=float)
    high = np.asarray(scene.upper_bounds, dtype=float)
    unit = _unit_samples(low.size, samples, seed)
    actuations = low + unit * (high - low)
    points = np.full((len(unit), 3), np.nan)
    rotations = np.full((len(unit), 3, 3), np.nan)
    frame = scene.effectors.frames[index]
    state = None
    for i in _nearest_neighbour_order(unit):
        result = scene.forward(actuations[i], initial_state=state, check_warnings=False)
        if not result.converged and state is not None:
            result = scene.forward(actuations[i], check_warnings=False)
        if result.converged:
            state = result.state
            points[i] = result.effector_positions[index]
            rotations[i] = result.rotations[frame]
    converged = np.all(np.isfinite(points), axis=1)
    count = int(np.count_nonzero(converged))
    if count < 3:
        raise RuntimeError(f'only {count} of {len(unit)} forward solves of {scene.name} '
                           'converged: no reachable set')
    points = points[converged]
    box_min, box_max = points.min(axis=0), points.max(axis=0)
    halfspaces, flat = _halfspaces(points)
    center, widest = _center(points, halfspaces, flat, box_min, box_max)
    return ReachableSet(effector=names[index], actuations=actuations[converged], points=points,
                        failed=len(unit) - count, box_min=box_min, box_max=box_max,
                        center=center, radii=_radii(halfspaces, flat, center),
                        widest_plane=widest, halfspaces=halfspaces, flat_planes=flat,
                        rotations=rotations[converged])


def _unit_samples(m, samples, seed):
    """Return the sampled actuations as fractions of the ranges, (samples, m) in [0, 1]."""
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)):
        raise ValueError(f'samples must be an integer, got {samples!r}')
    if samples < fewest_samples(m):
        raise ValueError(f'samples must be >= {fewest_samples(m)} (>= {MIN_SAMPLES} and the '
                         f'fixed samples of {m} actuators), got {samples}')
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f'seed must be a non-negative integer, got {seed!r}')
    fixed = np.vstack([np.zeros((1, m))] + [f * np.eye(m) for f in SINGLE_FRACTIONS]
                      + [np.outer(DIAGONAL_FRACTIONS, np.ones(m))])
    halton = qmc.Halton(d=m, scramble=True, seed=int(seed)).random(int(samples) - len(fixed))
    halton[1::2] = np.clip(2.0 * halton[1::2] - 0.5, 0.0, 1.0)
    return np.vstack([fixed, halton])


def fewest_samples(n_actuators):
    """
    Return the fewest samples :func:`sample_reachable_set` accepts for a scene.

    Parameters
    ----------
    n_actuators : int
        The scene's actuators.

    Returns
    -------
    int
        ``max(10, 4 n_actuators + 4)``: at least 10 and the fixed samples (the lower bounds,
        :data:`SINGLE_FRACTIONS` and :data:`DIAGONAL_FRACTIONS`).

    """
    return max(MIN_SAMPLES, 1 + len(SINGLE_FRACTIONS) * int(n_actuators)
               + len(DIAGONAL_FRACTIONS))


def _effector_index(effector, names):
    """Return the index of ``effector`` (an index or a name) in ``names``."""
    if isinstance(effector, str):
        if effector not in names:
            raise ValueError(f'no effector {effector!r}; the scene has {list(names)}')
        return names.index(effector)
    if isinstance(effector, bool) or not isinstance(effector, (int, np.integer)):
        raise ValueError(f'effector must be an index or a name, got {effector!r}')
    if not -len(names) <= effector < len(names):
        raise ValueError(f'effector index {effector} outside the {len(names)} effectors')
    return int(effector) % len(names)


def _nearest_neighbour_order(unit):
    """Return an order of the rows from row 0, each next the nearest unvisited one."""
    left = np.ones(len(unit), dtype=bool)
    order = [0]
    left[0] = False
    for _ in range(len(unit) - 1):
        distance = np.sum((unit - unit[order[-1]]) ** 2, axis=1)
        distance[~left] = np.inf
        order.append(int(np.argmin(distance)))
        left[order[-1]] = False
    return order


def _halfspaces(points):
    """Return the hull's half-spaces (f, 4) [m] and the planes a flat reach is flat across."""
    try:
        return ConvexHull(points).equations, ()
    except QhullError:
        pass
    rows, flat = [], []
    for plane, axes in PLANES.items():
        try:
            edges = ConvexHull(points[:, list(axes)]).equations
        except QhullError:
            flat.append(plane)
            continue
        extruded = np.zeros((len(edges), 4))
        extruded[:, list(axes)] = edges[:, :2]
        extruded[:, 3] = edges[:, 2]
        rows.append(extruded)
    return (np.vstack(rows) if rows else np.zeros((0, 4))), tuple(flat)


def _in_plane_norms(halfspaces, axes):
    """Return the length of each normal's component in the plane of ``axes``."""
    return np.linalg.norm(halfspaces[:, list(axes)], axis=1)


def _radius(halfspaces, point, axes):
    """Return the largest circle [m] around ``point`` in the plane of ``axes`` inside the hull."""
    if not len(halfspaces):
        return 0.0
    depth = -(halfspaces[:, :3] @ point + halfspaces[:, 3])
    if np.min(depth) < 0.0:
        return 0.0
    norms = _in_plane_norms(halfspaces, axes)
    crossing = norms > 1e-12
    return float(np.min(depth[crossing] / norms[crossing])) if np.any(crossing) else 0.0


def _radii(halfspaces, flat, point):
    """Return ``plane -> radius [m]`` of the largest circles around ``point`` (3,) [m]."""
    return {plane: 0.0 if plane in flat else _radius(halfspaces, point, axes)
            for plane, axes in PLANES.items()}


def _center(points, halfspaces, flat, box_min, box_max):
    """Return the reachable centre (3,) [m] and its widest plane (:func:`sample_reachable_set`)."""
    planes = [plane for plane in PLANES if plane not in flat]
    if not len(halfspaces) or not planes:
        return 0.5 * (box_min + box_max), None
    radii = np.array([[_radius(halfspaces, point, PLANES[plane]) for plane in planes]
                      for point in points])
    best = int(np.argmax(radii.max(axis=0)))
    others = np.delete(radii, best, axis=1)
    spread = -np.sum(np.abs(points - 0.5 * (box_min + box_max)), axis=1)
    # the largest circle in the widest plane, then the larger smaller other circle, then the
    # sample nearest the box middle (lexsort: last key first; ties keep the sample order)
    order = np.lexsort((spread, others.min(axis=1) if others.size else spread, radii[:, best]))
    return points[order[-1]].copy(), planes[best]
