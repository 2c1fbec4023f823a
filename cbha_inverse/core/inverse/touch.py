"""
Touch with a bounded force: a contact target's force rows in the actuation QP.

An effector given a contact target (a surface point ``s``, the surface's outward unit normal
``n``, pointing out of the touched solid toward the arm, and force bounds
``[f_min, f_max]`` [N]) presses on the surface through its collision sphere (radius ``ρ``,
centred at the effector point: ``docs/touch.md``). The inverse's model has no contact: in the
linear model of the tick (paper eq. 11, the effector's rows ``p_e' = offset_e + W_ea λ``) the
sphere would sink into a rigid surface by the predicted penetration

    d(λ) = ρ - nᵀ (p_e'(λ) - s),

and the force that holds it on the surface is ``f(λ) = d(λ) / c``, ``c = nᵀ W_ee n`` the
effector's compliance along ``n`` (``W_ee = J_e K⁻¹ J_eᵀ``; from the half-solves
``L⁻¹ J_eᵀ`` of the linearisation, ``c = |L⁻¹ J_eᵀ n|²``). The force is affine in ``λ``; its
bounds are two rows of the QP, written in metres as the obstacle rows are
(:mod:`cbha_inverse.core.inverse.obstacle_rows`, ``G λ + b ≥ 0``):

    d(λ) - c f_min ≥ 0,      c f_max - d(λ) ≥ 0,

each with the slack of :class:`cbha_inverse.core.inverse.qp.RowsQP`. The tracking term of
eq. 13 takes the virtual target: the effector's tangential target (its target projected onto
the surface's tangent plane through ``s``) at the depth ``c f_target`` below the sphere's
contact height, ``f_target`` the middle of the bounds, so the tracking pulls to the middle and
the rows keep the force within the bounds.
"""

import math
from typing import NamedTuple

from cbha_inverse.core.contact import frame_contact_force
import numpy as np

UNIT_TOLERANCE = 1e-6
"""A contact normal whose norm differs from 1 by more than this is refused."""
SURFACE_TOLERANCE = 1e-3
"""An obstacle whose surface passes within this [m] of the contact point, with its normal there
within :data:`NORMAL_AGREEMENT` of the contact normal, is the touched surface: the obstacle row
of the touching sphere against it gives way to the force rows."""
NORMAL_AGREEMENT = 0.99
"""Least cosine between an obstacle's normal at the contact point and the contact normal."""
FORCE_VIOLATION = 1e-5
"""A predicted penetration this far [m] outside the force rows means the bounds cannot hold."""


class Touch(NamedTuple):
    """
    One effector's contact target (validated by :func:`checked_touch`).

    Attributes
    ----------
    effector : int
        The effector's index.
    frame : int
        Its frame (the collision sphere's).
    radius : float  [m]
        The collision sphere's radius ``ρ``.
    point : (3,) ndarray  [m]
        ``s``, a point of the surface (world axes).
    normal : (3,) ndarray
        ``n``, the surface's outward unit normal (out of the touched solid).
    force_bounds : (2,) ndarray  [N]
        ``[f_min, f_max]``, ``0 ≤ f_min ≤ f_max < ∞``.

    """

    effector: int
    frame: int
    radius: float
    point: np.ndarray
    normal: np.ndarray
    force_bounds: np.ndarray

    @property
    def force_target(self):
        """Return the force the tracking term aims at [N]: the middle of the bounds."""
        return 0.5 * float(self.force_bounds[0] + self.force_bounds[1])


def at_height(touch, target, height):
    """
    Return ``target`` moved along the contact normal to ``height`` [m] above the surface.

    Its tangential part stays: ``target + n (height - nᵀ (target - s))``.

    Parameters
    ----------
    touch : Touch
        The contact target (``s``, ``n``).
    target : (3,) ndarray  [m]
        An effector target.
    height : float  [m]
        Signed height above the tangent plane through ``s`` along ``n``.

    Returns
    -------
    (3,) ndarray  [m]

    """
    normal = touch.normal
    return target + normal * (height - normal @ (target - touch.point))


def effector_index(names, effector):
    """
    Return the index of an effector given by index or name.

    Parameters
    ----------
    names : sequence of str
        The effectors' names.
    effector : int or str
        The effector.

    Returns
    -------
    int

    Raises
    ------
    ValueError
        On an unknown name or an index out of range.

    """
    names = tuple(names)
    if isinstance(effector, str):
        if effector not in names:
            raise ValueError(f'touch: unknown effector {effector!r} (effectors: '
                             f'{", ".join(names)})')
        return names.index(effector)
    if isinstance(effector, (int, np.integer)) and 0 <= effector < len(names):
        return int(effector)
    raise ValueError(f'touch: unknown effector {effector!r} (0..{len(names) - 1})')


def checked_touch(effectors, collision, effector, point, normal, force_bounds):
    """
    Return a validated :class:`Touch`.

    Parameters
    ----------
    effectors : cbha_inverse.core.actuation.effectors.PointEffectors
        The solver's effectors.
    collision : cbha_inverse.core.contact.CollisionSpheres or None
        The robot's collision spheres.
    effector : int or str
        The effector (index or name).
    point : (3,) array_like  [m]
        A point of the surface.
    normal : (3,) array_like
        The surface's outward unit normal.
    force_bounds : (2,) array_like  [N]
        ``[f_min, f_max]``.

    Returns
    -------
    Touch

    Raises
    ------
    ValueError
        On an unknown effector, an effector that is not the centre of a collision sphere (its
        point off its frame's origin, or no sphere on its frame), a point or normal that is not
        3 finite values, a normal not of unit length, or bounds that are not
        ``0 ≤ f_min ≤ f_max`` finite.

    """
    names = tuple(effectors.names)
    index = effector_index(names, effector)
    name = names[index]
    frame = int(effectors.frames[index])
    if np.any(effectors.offsets[index] != 0.0):
        raise ValueError(f'touch: effector {name!r} is off its frame origin: it touches '
                         'through the collision sphere centred at the origin')
    spheres = () if collision is None else collision.frames.tolist()
    if frame not in spheres:
        raise ValueError(f'touch: effector {name!r} has no collision sphere on its frame '
                         "(a scene's collision block)")
    radius = float(collision.radii[spheres.index(frame)])
    point = np.array(point, dtype=float)
    normal = np.array(normal, dtype=float)
    bounds = checked_force_bounds(force_bounds)
    if point.shape != (3,) or not np.all(np.isfinite(point)):
        raise ValueError(f'touch: point must be 3 finite values [m], got {point.tolist()}')
    if normal.shape != (3,) or not np.all(np.isfinite(normal)):
        raise ValueError(f'touch: normal must be 3 finite values, got {normal.tolist()}')
    length = float(np.linalg.norm(normal))
    if abs(length - 1.0) > UNIT_TOLERANCE:
        raise ValueError(f'touch: normal must be a unit vector, its norm is {length:.6g}')
    return Touch(index, frame, radius, point, normal / length, bounds)


def checked_force_bounds(force_bounds):
    """
    Return a contact target's force bounds, checked.

    Parameters
    ----------
    force_bounds : (2,) array_like  [N]
        ``[f_min, f_max]``.

    Returns
    -------
    (2,) ndarray  [N]

    Raises
    ------
    ValueError
        Unless they are two finite values with ``0 <= f_min <= f_max``.

    """
    bounds = np.array(force_bounds, dtype=float).reshape(-1)
    if bounds.shape != (2,) or not np.all(np.isfinite(bounds)) or not (
            0.0 <= bounds[0] <= bounds[1]):
        raise ValueError('touch: force bounds must be finite [f_min, f_max] N with '
                         f'0 <= f_min <= f_max, got {bounds.tolist()}')
    return bounds


def contact_compliance(columns, normal):
    """
    Return an effector's compliance along a direction, ``c = nᵀ J_e K⁻¹ J_eᵀ n`` [m/N].

    With ``K = L Lᵀ``: ``c = |L⁻¹ J_eᵀ n|²`` from the half-solved effector columns.

    Parameters
    ----------
    columns : (6n, 3) ndarray  [m/√(N m)]
        ``L⁻¹ J_eᵀ`` of the effector's three position rows.
    normal : (3,) ndarray
        ``n``.

    Returns
    -------
    float  [m/N]

    """
    along = columns @ normal
    return float(along @ along)


class TouchRows:
    """
    The contact targets of one solver and their force rows at its linearisation.

    Parameters
    ----------
    tick_data : cbha_inverse.core.inverse.tick_data.TickData
        The solver's tick buffers (``effector_columns``, ``w_ea``, ``offset``).
    names : tuple of str
        The effectors' names (the warnings').

    Attributes
    ----------
    touches : dict of int to Touch
        The contact targets by effector index.
    compliances : dict of int to float  [m/N]
        ``c`` of each touch at the last linearisation whose effector columns were half-solves.

    """

    def __init__(self, tick_data, names):
        """Start without contact targets."""
        self._data = tick_data
        self._names = tuple(names)
        self.touches = {}
        self.compliances = {}
        # per touching effector: (obstacles, touch, the names of the obstacles it touches)
        self._touched = {}

    @property
    def count(self):
        """Return the number of rows: two per contact target with a known compliance."""
        return 2 * len(self._ready())

    def put(self, touch):
        """Set (or replace) the contact target of ``touch.effector``; it keeps its compliance."""
        self.touches[touch.effector] = touch

    def clear(self, effector):
        """Drop the contact target of ``effector`` (index); return whether there was one."""
        self.compliances.pop(effector, None)
        return self.touches.pop(effector, None) is not None

    def _ready(self):
        """Return the touches with a compliance, in effector order."""
        return [self.touches[e] for e in sorted(self.touches) if e in self.compliances]

    def linearise(self):
        """
        Take each touch's compliance ``c`` at the tick data's linearisation.

        With half-solved effector columns (the block Cholesky); after the fallback chain the
        columns hold ``J_eᵀ`` and each touch keeps the compliance of the last half-solved
        linearisation (a touch set since has none: no rows until the next).
        """
        data = self._data
        if not data.half_solved[0]:
            return
        for e, touch in self.touches.items():
            self.compliances[e] = contact_compliance(
                data.effector_columns[:, 3 * e:3 * e + 3], touch.normal)

    def virtual_targets(self, targets):
        """
        Return the targets with each touching effector's replaced by its virtual target.

        The target projected onto the tangent plane through ``s``, at the height
        ``ρ - c f_target`` above it along ``n``: the free sphere ``c f_target`` inside the
        surface.

        Parameters
        ----------
        targets : (k, 3) ndarray  [m]
            The effector targets.

        Returns
        -------
        (k, 3) ndarray  [m]
            A C-ordered copy.

        """
        virtual = np.array(targets, dtype=float, order='C')
        for touch in self._ready():
            e = touch.effector
            virtual[e] = at_height(touch, virtual[e],
                                   touch.radius - self.compliances[e] * touch.force_target)
        return virtual

    def on_surface(self, targets):
        """
        Return the targets with each touching effector's sphere centre put on its surface.

        The tangential target at the height ``ρ`` above ``s`` along ``n``: the targets the
        obstacles' inside check reads (a contact target is on its surface, not inside it).

        Parameters
        ----------
        targets : (k, 3) ndarray  [m]
            The effector targets.

        Returns
        -------
        (k, 3) ndarray  [m]
            A copy.

        """
        moved = np.array(targets, dtype=float)
        for touch in self.touches.values():
            moved[touch.effector] = at_height(touch, moved[touch.effector], touch.radius)
        return moved

    def rows(self):
        """
        Return the force rows ``G λ + b ≥ 0`` [m] of the linearisation (module docstring).

        Returns
        -------
        matrix : (2t, m) ndarray  [m/Pa, m/N]
            ``∓ nᵀ W_ea`` of each touch: the lower bound's row, then the upper's.
        constant : (2t,) ndarray  [m]

        """
        data = self._data
        ready = self._ready()
        matrix = np.zeros((2 * len(ready), data.actuation.size))
        constant = np.zeros(2 * len(ready))
        for i, touch in enumerate(ready):
            e, normal = touch.effector, touch.normal
            compliance = self.compliances[e]
            # d(λ) = depth_free - slope λ
            slope = normal @ data.w_ea[3 * e:3 * e + 3]
            depth_free = touch.radius - normal @ (data.offset[3 * e:3 * e + 3] - touch.point)
            f_min, f_max = touch.force_bounds
            matrix[2 * i], constant[2 * i] = -slope, depth_free - compliance * f_min
            matrix[2 * i + 1], constant[2 * i + 1] = slope, compliance * f_max - depth_free
        return matrix, constant

    def outcome(self, actuation):
        """
        Return the predicted contact forces at ``actuation``, how far they leave the bounds, why.

        Parameters
        ----------
        actuation : (m,) ndarray  [Pa, N]
            ``λ`` of the tick.

        Returns
        -------
        forces : (k,) ndarray  [N]
            ``max(0, d(λ)) / c`` of each touching effector; NaN for the others and for a
            touch without a compliance yet.
        violation : float  [N]
            The largest distance of a predicted force outside its bounds (0 within).
        warnings : tuple of str
            One per touch whose bounds cannot hold (the surface out of the sphere's reach, or
            the force beyond the actuators).

        """
        data = self._data
        forces = np.full(data.effector_frames.size, math.nan)
        violation, warnings = 0.0, []
        for touch in self._ready():
            e, normal = touch.effector, touch.normal
            compliance = self.compliances[e]
            predicted = data.offset[3 * e:3 * e + 3] + data.w_ea[3 * e:3 * e + 3] @ actuation
            depth = touch.radius - normal @ (predicted - touch.point)
            force = max(depth, 0.0) / compliance
            forces[e] = force
            f_min, f_max = touch.force_bounds
            outside = max(f_min - depth / compliance, depth / compliance - f_max, 0.0)
            if outside * compliance <= FORCE_VIOLATION:
                continue
            violation = max(violation, outside)
            if depth < 0.0:
                warnings.append(f'touch of {self._names[e]!r}: the surface is out of reach, the '
                                f'sphere stays {-1e3 * depth:.1f} mm from it')
            else:
                warnings.append(f'touch of {self._names[e]!r}: predicted force {force:.3g} N '
                                f'outside [{f_min:.3g}, {f_max:.3g}] N')
        return forces, violation, tuple(warnings)

    def stacked(self, obstacle_rows):
        """
        Return the rows of the tick's QP: the obstacle rows, then the force rows [m].

        An obstacle row of a touching sphere against the surface it touches
        (:func:`touched_obstacles`) would hold the sphere ``obstacle_margin`` off the surface
        the force rows press it onto: it is left out.

        Parameters
        ----------
        obstacle_rows : cbha_inverse.core.inverse.obstacle_rows.ObstacleRows or None
            The obstacle rows of the linearisation (None without obstacles).

        Returns
        -------
        matrix : (r + 2t, m) ndarray  [m/Pa, m/N]
            ``G``.
        constant : (r + 2t,) ndarray  [m]
            ``b``.
        obstacle_count : int
            ``r``, the obstacle rows kept (first).

        """
        if obstacle_rows is None:
            matrix, constant = np.zeros((0, self._data.actuation.size)), np.zeros(0)
        else:
            matrix, constant = obstacle_rows.matrix, obstacle_rows.constant
        if not self.touches:
            return matrix, constant, constant.size
        if obstacle_rows is not None:
            kept = np.ones(constant.size, dtype=bool)
            for touch in self.touches.values():
                surfaces = self._surfaces(touch, obstacle_rows.obstacles)
                kept &= ~np.array([frame == touch.frame and name in surfaces for name, frame
                                   in zip(obstacle_rows.names, obstacle_rows.frames)], bool)
            matrix, constant = matrix[kept], constant[kept]
        force_matrix, force_constant = self.rows()
        return (np.vstack((matrix, force_matrix)), np.concatenate((constant, force_constant)),
                constant.size)

    def _surfaces(self, touch, obstacles):
        """Return the names of the obstacles ``touch`` touches (kept per obstacle set)."""
        known = self._touched.get(touch.effector)
        if known is None or known[0] is not obstacles or known[1] is not touch:
            known = (obstacles, touch, touched_obstacles(obstacles, touch.point, touch.normal))
            self._touched[touch.effector] = known
        return known[2]


def touched_obstacles(obstacles, point, normal):
    """
    Return the names of the obstacles whose surface is the contact target's.

    Their surface passes within :data:`SURFACE_TOLERANCE` of ``point`` and their outward normal
    there agrees with ``normal`` (cosine at least :data:`NORMAL_AGREEMENT`).

    Parameters
    ----------
    obstacles : sequence of cbha_inverse.core.obstacles.Obstacle
        The obstacles.
    point : (3,) ndarray  [m]
        ``s``.
    normal : (3,) ndarray
        ``n``.

    Returns
    -------
    tuple of str

    """
    names = []
    for obstacle in obstacles:
        query = obstacle.signed_distance(point[None, :])
        if (abs(query.distance[0]) <= SURFACE_TOLERANCE
                and query.normal[0] @ normal >= NORMAL_AGREEMENT):
            names.append(obstacle.name)
    return tuple(names)


def measured_touch_force(contacts, frame, normal):
    """
    Return the plant's contact force on a frame's sphere along a normal [N].

    The frame's contact force (:func:`cbha_inverse.core.contact.frame_contact_force`, the
    plant's :class:`cbha_inverse.core.contact.Contacts`) along ``n``: the force with which the
    sphere presses the surface (0 without contact).

    Parameters
    ----------
    contacts : cbha_inverse.core.contact.Contacts
        The plant's contacts.
    frame : int
        The touching sphere's frame.
    normal : (3,) array_like
        ``n``.

    Returns
    -------
    float  [N]

    """
    return float(frame_contact_force(contacts, frame) @ np.asarray(normal, dtype=float))
