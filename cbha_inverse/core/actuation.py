"""
Actuators of a frame chain: cables (tendons) and pressure cavities (paper §IV, DESIGN §5).

Every actuator contributes one column of the actuation Jacobian transpose ``J_aᵀ`` (paper eq. 9):
the wrenches it applies to the frames per unit actuation (unit tension in N, unit pressure in Pa).
Here a column is stored batch-first as ``(n + 1, 6)``: one wrench (Fx, Fy, Fz, Mx, My, Mz) per
frame, world axes, at the frame origin; row 0 (the fixed base) is kept so that the indices match
the frames and is dropped by the solver.

Sign conventions (the actuator's virtual work is ``λ · dδ_a``):

- cable: ``λ ≥ 0`` is the tension; ``δ_a`` is the cable *shortening* (pulled-in length), so the
  column is ``-d(length)/dq`` and a positive tension shortens the cable;
- cavity: ``λ`` is the gauge pressure; ``δ_a`` is the cavity volume, so the column is
  ``+d(volume)/dq`` and a positive pressure inflates the cavity.

With increments ``dq`` applied by :func:`cbha_inverse.core.chain.retract` (``dx`` and world-axis
``dθ`` per frame), ``J_a dq = dδ_a`` to first order; the tests check this against finite
differences.

Each actuator group evaluates all its actuators at once (vectorised over routing points,
vertices, triangles); :class:`ActuatorSet` stacks the groups in the scene's actuator order.
"""

from dataclasses import dataclass

from cbha_inverse.core.se3 import hat
import numpy as np
import scipy.sparse as sp


def cross(a, b):
    """
    Return the row-wise cross product ``a × b`` (faster than ``numpy.cross`` for small batches).

    Parameters
    ----------
    a, b : (..., 3) ndarray
        Vectors.

    Returns
    -------
    (..., 3) ndarray
        ``a × b``.

    """
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def point_wrenches(levers, forces):
    """
    Map forces applied at points to wrenches at frame origins (paper Fig. 4, rigid mapping).

    A force ``F`` at ``p = x_f + r`` does the virtual work ``F · (dx_f + dθ_f × r)``, so the
    wrench at the frame origin is ``[F; r × F]`` (world axes).

    Parameters
    ----------
    levers : (P, 3) ndarray  [m]
        ``r = p - x_f``, world axes.
    forces : (P, 3) ndarray  [N]
        Forces, world axes.

    Returns
    -------
    (P, 6) ndarray  [N, N*m]
        Wrenches at the frame origins.

    """
    return np.concatenate([forces, cross(levers, forces)], axis=1)


@dataclass(frozen=True)
class Cable:
    """
    One cable (tendon) routed through points fixed to frames.

    Attributes
    ----------
    name : str
        Actuator name.
    frames : (P,) ndarray of int
        Frame index of each routing point, in routing order from the actuator (base) end.
    offsets : (P, 3) ndarray  [m]
        Routing points in the axes of their frame, relative to its origin.
    max_tension : float  [N]
        Upper bound of the tension (``inf`` if unbounded).

    """

    name: str
    frames: np.ndarray
    offsets: np.ndarray
    max_tension: float = np.inf

    def __post_init__(self):
        """Validate shapes."""
        frames = np.asarray(self.frames, dtype=int).reshape(-1)
        offsets = np.asarray(self.offsets, dtype=float).reshape(-1, 3)
        if frames.size < 2 or offsets.shape[0] != frames.size:
            raise ValueError(f'cable {self.name!r}: need >= 2 routing points with one offset each')
        object.__setattr__(self, 'frames', frames)
        object.__setattr__(self, 'offsets', offsets)


class CableGroup:
    """
    All cables of a scene, evaluated together (DESIGN §5).

    The force of a cable on a routing point is the sum of the unit vectors toward its neighbouring
    routing points (the last point pulls toward the previous one); it is mapped rigidly to the
    wrench of the point's frame. Without friction this is exactly ``-d(length)/dq``.

    Parameters
    ----------
    cables : sequence of Cable
        The cables, in column order.
    n_frames : int
        Number of frames of the chain (``n + 1``, base included).

    """

    def __init__(self, cables, n_frames):
        """Precompute index arrays and the scatter matrices of the group."""
        self.cables = tuple(cables)
        self.names = tuple(c.name for c in self.cables)
        self.n_frames = int(n_frames)
        m = len(self.cables)
        frames, offsets, owner, starts = [], [], [], []
        count = 0
        for j, cable in enumerate(self.cables):
            if cable.frames.min() < 0 or cable.frames.max() >= n_frames:
                raise ValueError(f'cable {cable.name!r} names a frame outside 0..{n_frames - 1}')
            p = cable.frames.size
            frames.append(cable.frames)
            offsets.append(cable.offsets)
            owner.append(np.full(p, j))
            starts.append(count + np.arange(p - 1))
            count += p
        self.frames = np.concatenate(frames)
        self.offsets = np.concatenate(offsets)
        owner = np.concatenate(owner)
        self.segment_start = np.concatenate(starts)
        self.segment_end = self.segment_start + 1
        n_points, n_segments = self.frames.size, self.segment_start.size
        segment_owner = owner[self.segment_start]
        rows = np.arange(n_segments)
        incidence = (sp.csr_matrix((np.ones(n_segments), (self.segment_start, rows)),
                                   shape=(n_points, n_segments))
                     - sp.csr_matrix((np.ones(n_segments), (self.segment_end, rows)),
                                     shape=(n_points, n_segments)))
        self._point_force = incidence.toarray()
        scatter = np.zeros((m * self.n_frames, n_points))
        scatter[owner * self.n_frames + self.frames, np.arange(n_points)] = 1.0
        self._scatter = scatter
        self._length_sum = np.zeros((m, n_segments))
        self._length_sum[segment_owner, rows] = 1.0
        self.upper_bounds = np.array([c.max_tension for c in self.cables], dtype=float)
        self.lower_bounds = np.zeros(m)
        self._segment_owner = segment_owner
        self._point_owner = owner
        self._tangent_index = _span_tangent_index(self.frames, self.segment_start,
                                                  self.segment_end, self.n_frames)

    @property
    def n_actuators(self):
        """Return the number of cables."""
        return len(self.cables)

    def routing_points(self, positions, rotations):
        """
        Return the world positions of all routing points and their levers.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations (frame axes → world).

        Returns
        -------
        points, levers : (P, 3) ndarray  [m]
            Routing points and ``point - frame origin`` (world axes).

        """
        levers = np.einsum('pij,pj->pi', rotations[self.frames], self.offsets)
        return positions[self.frames] + levers, levers

    def lengths(self, positions, rotations):
        """
        Return the routed length of every cable.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations (frame axes → world).

        Returns
        -------
        (m,) ndarray  [m]
            Sum of the straight spans between consecutive routing points.

        """
        return self._length_sum @ self._spans(positions, rotations)[2]

    def _spans(self, positions, rotations):
        """Return the routing-point levers, the span unit vectors and the span lengths."""
        points, levers = self.routing_points(positions, rotations)
        spans = points[self.segment_end] - points[self.segment_start]
        span_lengths = np.sqrt(np.einsum('si,si->s', spans, spans))
        return levers, spans / span_lengths[:, None], span_lengths

    def evaluate(self, positions, rotations, displacements=True):
        """
        Return the Jacobian columns and the displacements of all cables.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations (frame axes → world).

        displacements : bool
            Unused (the lengths come with the columns at no cost).

        Returns
        -------
        wrenches : (m, n + 1, 6) ndarray  [N, N*m per N]
            Frame wrenches per unit tension (columns of ``J_aᵀ``).
        displacements : (m,) ndarray  [m]
            ``-length``: the cable shortening up to a constant (``δ_a``).

        """
        levers, units, span_lengths = self._spans(positions, rotations)
        forces = self._point_force @ units
        wrenches = self._scatter @ point_wrenches(levers, forces)
        return (wrenches.reshape(self.n_actuators, self.n_frames, 6),
                -(self._length_sum @ span_lengths))

    def load_tangent(self, positions, rotations, tensions, symmetric=True):
        """
        Return the load stiffness of the cables, ``-d(J_aᵀ λ)/dq`` (exact or its symmetric part).

        Cable forces follow the structure, so they add a stiffness to the tangent of the
        equilibrium (paper eq. 9-10): per span ``s`` with unit direction ``u``, length ``ℓ`` and
        tension ``λ``, ``λ D_sᵀ (I - u uᵀ)/ℓ D_s`` (``D_s`` maps increments to the change of the
        span vector; positive semi-definite: it stabilises the compressed backbone), and per
        routing point with lever ``r`` and force ``F`` the moment term ``-F^ r^ = (F·r) I - r Fᵀ``
        on its frame's rotations (turning the frame turns the lever), whose symmetric part is
        ``(F·r) I - (r Fᵀ + F rᵀ)/2`` and skew part ``½ hat(r × F)``. Without it a
        tendon-compressed chain can look unstable to Newton's method.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations.
        tensions : (m,) ndarray  [N]
            Cable tensions.
        symmetric : bool
            True: the symmetric part (for the Cholesky of the control tick); False: the exact
            tangent (Newton converges quadratically with it, linearly without the skew part).

        Returns
        -------
        (6n, 6n) ndarray  [N/m, N, N*m]
            Over frames 1..n (world-axis increments), to add to the structural tangent.

        """
        levers, units, lengths = self._spans(positions, rotations)
        start, end = self.segment_start, self.segment_end
        scale = tensions[self._segment_owner] / lengths
        proj = -scale[:, None, None] * units[:, :, None] * units[:, None, :]
        proj[:, 0, 0] += scale
        proj[:, 1, 1] += scale
        proj[:, 2, 2] += scale
        lever = np.stack([levers[start], levers[end]], axis=1)
        # B = [I; r^] (6 x 3) for the start and end points of every span
        b = np.zeros((len(start), 2, 6, 3))
        b[:, :, 0, 0] = b[:, :, 1, 1] = b[:, :, 2, 2] = 1.0
        b[:, :, 3:, :] = hat(lever)
        bp = np.matmul(b, proj[:, None])
        blocks = np.matmul(bp[:, :, None], np.swapaxes(b, 2, 3)[:, None, :])
        blocks[:, 0, 1] *= -1.0
        blocks[:, 1, 0] *= -1.0
        forces = (self._point_force @ units) * tensions[self._point_owner][:, None]
        fr = np.einsum('pi,pi->p', forces, levers)
        moment = -levers[:, :, None] * forces[:, None, :]
        if symmetric:
            moment = 0.5 * (moment + np.swapaxes(moment, 1, 2))
        moment[:, 0, 0] += fr
        moment[:, 1, 1] += fr
        moment[:, 2, 2] += fr
        size = 6 * self.n_frames
        dense = np.bincount(self._tangent_index,
                            np.concatenate([blocks.reshape(-1), moment.reshape(-1)]),
                            minlength=size * size).reshape(size, size)
        return dense[6:, 6:]


def _span_tangent_index(frames, start, end, n_frames):
    """Flat dense indices of the span blocks and point moment blocks of a cable group."""
    size = 6 * n_frames
    f = np.stack([frames[start], frames[end]], axis=1)
    i6 = np.arange(6)
    rows = 6 * f[:, :, None, None, None] + i6[None, None, None, :, None]
    cols = 6 * f[:, None, :, None, None] + i6[None, None, None, None, :]
    span_index = (rows * size + cols).reshape(-1)
    i3 = np.arange(3)
    prow = 6 * frames[:, None, None] + 3 + i3[None, :, None]
    pcol = 6 * frames[:, None, None] + 3 + i3[None, None, :]
    return np.concatenate([span_index, (prow * size + pcol).reshape(-1)])


class ActuatorSet:
    """
    The actuators of a scene: groups (cables, cavities) stacked in column order.

    Parameters
    ----------
    groups : sequence
        Objects with ``names``, ``n_actuators``, ``lower_bounds``, ``upper_bounds`` and
        ``evaluate(positions, rotations) -> (wrenches (m_g, n + 1, 6), displacements (m_g,))``
        (:class:`CableGroup`, :class:`cbha_inverse.core.cavity.CavityGroup`,
        :class:`cbha_inverse.core.cavity.LinearCavityGroup`).
    n_frames : int
        Number of frames (base included).
    order : sequence of str, optional
        Actuator names in the wanted column order (default: group order).

    """

    def __init__(self, groups, n_frames, order=None):
        """Index the groups' columns in the requested order."""
        self.groups = tuple(g for g in groups if g.n_actuators)
        self.n_frames = int(n_frames)
        names = [name for g in self.groups for name in g.names]
        if len(set(names)) != len(names):
            raise ValueError(f'duplicate actuator names in {names}')
        order = list(names if order is None else order)
        if sorted(order) != sorted(names):
            raise ValueError(f'actuator order {order} does not match the actuators {names}')
        position = {name: k for k, name in enumerate(order)}
        self.names = tuple(order)
        self._columns = [np.array([position[name] for name in g.names], dtype=int)
                         for g in self.groups]
        self.lower_bounds = np.empty(len(order))
        self.upper_bounds = np.empty(len(order))
        for g, cols in zip(self.groups, self._columns):
            self.lower_bounds[cols] = g.lower_bounds
            self.upper_bounds[cols] = g.upper_bounds

    @property
    def n_actuators(self):
        """Return the number of actuators ``m``."""
        return len(self.names)

    def evaluate(self, positions, rotations, displacements=True):
        """
        Return all Jacobian columns and actuator displacements.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations (frame axes → world).
        displacements : bool
            Also evaluate ``δ_a`` (a group may return ``None`` otherwise).

        Returns
        -------
        wrenches : (m, n + 1, 6) ndarray
            Columns of ``J_aᵀ`` (frame wrenches per unit actuation, world axes).
        displacements : (m,) ndarray
            ``δ_a`` up to constants (cable shortening, cavity volume).

        """
        if len(self.groups) == 1:
            return self.groups[0].evaluate(positions, rotations, displacements)
        wrenches = np.empty((self.n_actuators, self.n_frames, 6))
        out = np.empty(self.n_actuators)
        for g, cols in zip(self.groups, self._columns):
            wrenches[cols], out[cols] = g.evaluate(positions, rotations, True)
        return wrenches, out

    def load_tangent(self, positions, rotations, actuation, symmetric=True):
        """
        Return the load stiffness ``-d(J_aᵀ λ)/dq`` of the groups that provide one.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations.
        actuation : (m,) ndarray
            Actuation in column order.
        symmetric : bool
            Symmetric part only (for a Cholesky factorization).

        Returns
        -------
        (6n, 6n) ndarray or None
            ``None`` when no group has a load stiffness.

        """
        total = None
        for g, cols in zip(self.groups, self._columns):
            if hasattr(g, 'load_tangent'):
                part = g.load_tangent(positions, rotations, actuation[cols], symmetric)
                total = part if total is None else total + part
        return total

    def loads(self, positions, rotations, actuation):
        """
        Return the frame wrenches ``J_aᵀ λ`` of an actuation.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations.
        actuation : (m,) ndarray  [N or Pa]
            Tensions / pressures.

        Returns
        -------
        (n + 1, 6) ndarray  [N, N*m]
            Wrenches per frame, world axes (row 0 acts on the fixed base).

        """
        wrenches, _ = self.evaluate(positions, rotations)
        return np.einsum('m,mfa->fa', np.asarray(actuation, dtype=float), wrenches)
