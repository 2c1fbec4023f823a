"""
Contact between the robot's collision spheres and obstacles: frictionless penalty loads.

The robot's collision geometry is a set of spheres centred at frame origins
(:class:`CollisionSpheres`, declared by a scene's ``collision`` block, ``docs/obstacles.md``).
A sphere of radius ``ρ`` centred at ``x`` penetrates an obstacle by

    p = max(0, ρ - φ(x))

with ``φ`` the obstacle's signed distance (:meth:`cbha_inverse.core.obstacles.Obstacle.
signed_distance`, normal ``n = ∇φ``, Hessian ``H = ∇n``). :class:`PenaltyContact` pushes it out
with the frictionless penalty force ``f = k p n`` (``k`` the contact stiffness [N/m]) on the
sphere's frame, at its origin (no moment), and gives the exact load stiffness of that force,

    -df/dx = k (n nᵀ - p H)      (while p > 0),

for :func:`cbha_inverse.core.statics.solve_static`'s ``load_function`` / ``load_tangent``: Newton
converges quadratically once the set of contacts settles. The tangent counts a sphere from the
moment it touches (within :data:`TOUCH_MARGIN`), where the force is still zero: a sphere that
has just reached an obstacle brings its stiffness into the next step. A tangent is blind to a
contact that has not begun, so a Newton step from outside would pass through the obstacle;
:meth:`PenaltyContact.step_limit` shortens it to where the first new contact begins (the
``load_step_limit`` of :func:`~cbha_inverse.core.statics.solve_static`). The penetration of an
equilibrium is ``|f| / k``: the penalty trades accuracy (a stiffer ``k``) against conditioning.
"""

from dataclasses import dataclass
from typing import NamedTuple

from cbha_inverse.core.obstacles import (check_names, pack_obstacles, pairwise_signed_distance,
                                         read_only_packed, SignedDistance, sphere_gaps)
import numpy as np

TOUCH_MARGIN = 1.0e-9
"""A sphere this close to an obstacle [m] touches it: its stiffness enters the tangent, and a
step shortened to a new contact ends this deep inside it."""


@dataclass(frozen=True, eq=False)
class CollisionSpheres:
    """
    The robot's collision spheres, centred at frame origins.

    Parameters
    ----------
    frames : (k,) array_like of int
        The frame of each sphere (1..n: frame 0, the base, never moves).
    radii : (k,) array_like  [m]
        Their radii (> 0).

    Raises
    ------
    ValueError
        If the frames are not distinct positive integers or a radius is not positive and
        finite.

    """

    frames: np.ndarray
    radii: np.ndarray

    def __post_init__(self):
        """Check and freeze the arrays."""
        frames = np.array(self.frames, dtype=int).reshape(-1)
        radii = np.array(self.radii, dtype=float).reshape(-1)
        if frames.shape != radii.shape:
            raise ValueError(f'collision spheres: {frames.size} frames but {radii.size} radii')
        if np.any(frames < 1) or np.unique(frames).size != frames.size:
            raise ValueError('collision spheres: frames must be distinct and >= 1 (frame 0, '
                             'the base, does not move)')
        if not np.all(np.isfinite(radii)) or np.any(radii <= 0.0):
            raise ValueError('collision spheres: radii must be finite and > 0')
        frames.flags.writeable = radii.flags.writeable = False
        object.__setattr__(self, 'frames', frames)
        object.__setattr__(self, 'radii', radii)

    def centres(self, positions):
        """Return the spheres' centres [m], (k, 3), from the frame origins (n + 1, 3)."""
        return np.asarray(positions, dtype=float)[self.frames]

    def clearances(self, positions, obstacles):
        """
        Return the gap of every sphere to every obstacle (negative: penetration).

        Parameters
        ----------
        positions : (n + 1, 3) array_like  [m]
            Frame origins.
        obstacles : sequence of cbha_inverse.core.obstacles.Obstacle
            The obstacles.

        Returns
        -------
        (k, len(obstacles)) ndarray  [m]

        """
        return sphere_gaps(obstacles, self.centres(positions), self.radii)


class Contacts(NamedTuple):
    """
    The contacts of a state: one row per penetrating (sphere, obstacle) pair.

    Attributes
    ----------
    frames : (c,) ndarray of int
        The sphere's frame.
    obstacles : tuple of str
        The obstacle's name.
    points : (c, 3) ndarray  [m]
        The closest point of the obstacle's surface to the sphere's centre (base frame).
    normals : (c, 3) ndarray
        The obstacle's outward unit normal there (the force's direction).
    penetrations : (c,) ndarray  [m]
        ``ρ - φ(x) > 0``.
    forces : (c, 3) ndarray  [N]
        The penalty force on the sphere, ``k p n``.

    """

    frames: np.ndarray
    obstacles: tuple
    points: np.ndarray
    normals: np.ndarray
    penetrations: np.ndarray
    forces: np.ndarray


NO_CONTACTS = Contacts(np.zeros(0, dtype=int), (), np.zeros((0, 3)), np.zeros((0, 3)),
                       np.zeros(0), np.zeros((0, 3)))
"""The contacts of a state that touches nothing."""


class PenaltyContact:
    """
    Frictionless penalty contact of collision spheres with obstacles (module docstring).

    Parameters
    ----------
    spheres : CollisionSpheres
        The robot's spheres.
    obstacles : sequence of cbha_inverse.core.obstacles.Obstacle
        The obstacles (names distinct).
    stiffness : float  [N/m]
        The penalty stiffness ``k`` (> 0).
    n_links : int
        Links of the chain (frames 1..n carry the loads).

    Raises
    ------
    ValueError
        On a non-positive stiffness, a sphere frame beyond the chain or two obstacles of one name.

    """

    def __init__(self, spheres, obstacles, stiffness, n_links):
        """Check and keep the parts."""
        if not (np.isfinite(stiffness) and stiffness > 0.0):
            raise ValueError(f'contact stiffness must be finite and > 0, got {stiffness!r}')
        if spheres.frames.size and spheres.frames.max() > n_links:
            raise ValueError(f'collision spheres: frame {spheres.frames.max()} beyond the '
                             f'chain (frames 1..{n_links})')
        self.spheres = spheres
        self.obstacles = check_names(obstacles)
        self._packed = read_only_packed(pack_obstacles(self.obstacles))
        self.stiffness = float(stiffness)
        self.n_links = int(n_links)

    def _query(self, positions):
        """
        Return the signed distance of every sphere's centre to every obstacle, and the depths.

        Returns
        -------
        query : cbha_inverse.core.obstacles.SignedDistance
            Of sphere ``s`` to obstacle ``j`` at ``[s, j]`` (k, o leading dimensions).
        penetrations : (k, o) ndarray  [m]
            ``ρ - φ(x)`` of every pair (negative: apart; -inf for every pair of a non-finite
            state, which touches nothing).

        """
        centres = self.spheres.centres(positions)
        if not np.all(np.isfinite(centres)):
            # a diverged trial state: no pair touches, its residual tells the static solver
            k, o = centres.shape[0], len(self.obstacles)
            query = SignedDistance(np.full((k, o), np.inf), np.zeros((k, o, 3)),
                                   np.zeros((k, o, 3)), np.zeros((k, o, 3, 3)))
        else:
            query = pairwise_signed_distance(self._packed, centres, check=False)
        return query, self.spheres.radii[:, None] - query.distance

    def _add_frame_blocks(self, out, blocks):
        """Add the (k, 3, 3) ``blocks`` onto the translation block of each sphere's frame."""
        rows = 6 * (self.spheres.frames - 1)[:, None] + np.arange(3)
        out[rows[:, :, None], rows[:, None, :]] += blocks

    def wrenches(self, state):
        """
        Return the contact wrenches on frames 1..n, world axes (``load_function``).

        Parameters
        ----------
        state : cbha_inverse.core.chain.ChainState
            The frames.

        Returns
        -------
        (n, 6) ndarray  [N, N*m]
            ``k p n`` on the force rows of each penetrating sphere's frame (no moments).

        """
        out = np.zeros((self.n_links, 6))
        query, penetrations = self._query(state.positions)
        forces = self.stiffness * np.maximum(penetrations, 0.0)[:, :, None] * query.normal
        out[self.spheres.frames - 1, 0:3] += forces.sum(axis=1)
        return out

    def tangent(self, state):
        """
        Return the contact load stiffness ``-d wrenches / dq`` (``load_tangent``).

        Parameters
        ----------
        state : cbha_inverse.core.chain.ChainState
            The frames.

        Returns
        -------
        (6n, 6n) ndarray  [N/m]
            ``k (n nᵀ - p H)`` on the translation block of each touching sphere's frame
            (penetration above ``-TOUCH_MARGIN``: the derivative from the contact side where
            the contact begins; world-axis increments as
            :func:`cbha_inverse.core.chain.retract`).

        """
        out = np.zeros((6 * self.n_links, 6 * self.n_links))
        query, penetrations = self._query(state.positions)
        normal = query.normal
        blocks = self.stiffness * (normal[:, :, :, None] * normal[:, :, None, :]
                                   - np.maximum(penetrations, 0.0)[:, :, None, None]
                                   * query.curvature)
        touching = penetrations > -TOUCH_MARGIN
        self._add_frame_blocks(out, np.where(touching[:, :, None, None], blocks, 0.0).sum(axis=1))
        return out

    def step_limit(self, state, stepped):
        """
        Return the fraction of a step from ``state`` to ``stepped`` before a new contact begins.

        For each pair apart at ``state`` (gap above ``TOUCH_MARGIN``) and penetrating at
        ``stepped``, the gap interpolated linearly along the step reaches ``-TOUCH_MARGIN`` at
        ``(g0 + margin) / (g0 - g1)``; the smallest of these (1 without a new contact). The
        ``load_step_limit`` of :func:`cbha_inverse.core.statics.solve_static`.

        Parameters
        ----------
        state, stepped : cbha_inverse.core.chain.ChainState
            The start and the end of the full step.

        Returns
        -------
        float
            In (0, 1].

        """
        before = -self._query(state.positions)[1]
        after = -self._query(stepped.positions)[1]
        entering = (before > TOUCH_MARGIN) & (after < 0.0)
        if not np.any(entering):
            return 1.0
        fractions = (before[entering] + TOUCH_MARGIN) / (before[entering] - after[entering])
        return min(1.0, float(fractions.min()))

    def contacts(self, state):
        """
        Return the contacts of a state (one row per penetrating sphere and obstacle).

        Parameters
        ----------
        state : cbha_inverse.core.chain.ChainState
            The frames.

        Returns
        -------
        Contacts
            Ordered by obstacle, then by sphere.

        """
        query, penetrations = self._query(state.positions)
        obstacle, sphere = np.nonzero(penetrations.T > 0.0)
        if not sphere.size:
            return NO_CONTACTS
        depths, normals = penetrations[sphere, obstacle], query.normal[sphere, obstacle]
        return Contacts(self.spheres.frames[sphere],
                        tuple(self.obstacles[j].name for j in obstacle),
                        query.closest[sphere, obstacle], normals, depths,
                        self.stiffness * depths[:, None] * normals)
