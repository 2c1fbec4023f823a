"""
Cables (tendons) of a frame chain: their routing data (paper Sec. IV).

A cable is routed through points fixed to frames; its force on each routing point is the sum of
the unit vectors toward its neighbouring points (the last point pulls toward the previous one),
mapped rigidly to the wrench of the point's frame: one column of ``J_aᵀ`` per cable (paper eq. 9),
``-d(length)/dq`` without friction, ``λ ≥ 0`` the tension. :class:`CableGroup` indexes the
routing of all cables; :class:`CableTerms` indexes every cable of a scene and the blocks of their
load stiffness for the compiled :func:`cbha_inverse.core._kernels.cables.cable_pass` (the one
implementation of the cable equations; the numpy version is a test oracle,
``test/oracles/actuation.py``). :class:`RoutedLengths` gives the routed length of cables at a
pose and its gradient (:func:`cbha_inverse.core._kernels.cables.routing_lengths_into`, the same
routing geometry): the tendon lengths, and the string potentiometers'.
"""

from dataclasses import dataclass

from cbha_inverse.core._kernels.cables import routing_lengths_into
import numpy as np


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
    gain : float  [-]
        Factor on the cable's force per unit tension (its column of ``J_aᵀ``, its load and its
        load stiffness): the tension acting along the routing is ``gain`` times the commanded
        one (a scene's ``calibration.actuator_gain``; 1 = the ideal cable).
    axial_stiffness : float  [N]
        ``EA`` of the cable, its stretch under tension (``inf``: inextensible); only a
        displacement-commanded cable stretches (:mod:`cbha_inverse.core.actuation.drives`).

    """

    name: str
    frames: np.ndarray
    offsets: np.ndarray
    max_tension: float = np.inf
    gain: float = 1.0
    axial_stiffness: float = np.inf

    def __post_init__(self):
        """Validate shapes and the gain."""
        frames = np.asarray(self.frames, dtype=int).reshape(-1)
        offsets = np.asarray(self.offsets, dtype=float).reshape(-1, 3)
        if frames.size < 2 or offsets.shape[0] != frames.size:
            raise ValueError(f'cable {self.name!r}: need >= 2 routing points with one offset each')
        if not (np.isfinite(self.gain) and self.gain > 0.0):
            raise ValueError(f'cable {self.name!r}: gain must be finite and > 0, got {self.gain}')
        if not self.axial_stiffness > 0.0:
            raise ValueError(f'cable {self.name!r}: axial_stiffness must be > 0 (inf: '
                             f'inextensible), got {self.axial_stiffness}')
        object.__setattr__(self, 'frames', frames)
        object.__setattr__(self, 'offsets', offsets)


class CableGroup:
    """
    All cables of a scene, evaluated together.

    The force of a cable on a routing point is the sum of the unit vectors toward its neighbouring
    routing points (the last point pulls toward the previous one), times the cable's gain; it is
    mapped rigidly to the wrench of the point's frame. Without friction this is exactly
    ``-gain d(length)/dq``.

    Parameters
    ----------
    cables : sequence of Cable
        The cables, in column order.
    n_frames : int
        Number of frames of the chain (``n + 1``, base included).

    """

    def __init__(self, cables, n_frames):
        """Index the routing points and the spans between them."""
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
        self.frames = np.ascontiguousarray(np.concatenate(frames), dtype=np.int64)
        self.offsets = np.ascontiguousarray(np.concatenate(offsets), dtype=float)
        owner = np.concatenate(owner).astype(np.int64)
        self.segment_start = np.concatenate(starts).astype(np.int64)
        self.segment_end = self.segment_start + 1
        self.segment_owner = owner[self.segment_start]
        self.point_owner = owner
        self.upper_bounds = np.array([c.max_tension for c in self.cables], dtype=float)
        self.lower_bounds = np.zeros(m)
        self.gains = np.array([c.gain for c in self.cables], dtype=float)
        self.axial_stiffness = np.array([c.axial_stiffness for c in self.cables], dtype=float)
        for routing_array in self.routing:
            # constants of the compiled kernels, which take them read-only (one compiled type)
            routing_array.flags.writeable = False

    @property
    def n_actuators(self):
        """Return the number of cables."""
        return len(self.cables)

    @property
    def routing(self):
        """
        Return the routing arrays of the compiled cable kernels (C-contiguous, int64 indices).

        Returns
        -------
        tuple of ndarray
            Frames (P,), offsets (P, 3) [m], span start, end and owner (S,), point owner (P,):
            the routing arguments of :func:`cbha_inverse.core._kernels.cables.cable_pass` and
            :func:`cbha_inverse.core._kernels.cables.routing_lengths_into`.

        """
        return (self.frames, self.offsets, self.segment_start, self.segment_end,
                self.segment_owner, self.point_owner)


class RoutedLengths:
    """
    The routed length of every cable of a group at a pose, and its gradient.

    A cable's length is the sum of its straight spans between routing points; its gradient in
    the retract increments of frames 1..n is minus its column of ``J_aᵀ`` at unit gain (paper
    eq. 9): ``dℓ = -J_a dq`` without friction.

    Parameters
    ----------
    group : CableGroup
        The cables (their gains do not enter: a length is geometry).

    """

    def __init__(self, group):
        """Allocate the lengths, the Jacobian and the scratch of the compiled evaluation."""
        self.group = group
        self.names = group.names
        self.routing = group.routing
        c, n_frames = group.n_actuators, group.n_frames
        n_points, n_spans = self.routing[0].size, self.routing[2].size
        unit_gains = np.ones(c)
        unit_gains.flags.writeable = False
        self._lengths = np.zeros(c)
        self._jacobian = np.zeros((c, 6 * (n_frames - 1)))
        # the scratch of routing_lengths_into: levers, points, forces (P, 3), span units (S, 3)
        # and lengths (S,), unit gains (c,)
        self._scratch = (np.zeros((n_points, 3)), np.zeros((n_points, 3)),
                         np.zeros((n_points, 3)), np.zeros((n_spans, 3)), np.zeros(n_spans),
                         unit_gains)

    def lengths_and_jacobian(self, positions, rotations):
        """
        Return the lengths and their Jacobian ``d(length)/dq``.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations.

        Returns
        -------
        lengths : (c,) ndarray  [m]
        jacobian : (c, 6n) ndarray  [-, m/rad]
            In the retract increments ``(dx_f, dθ_f)`` of frames 1..n (world axes). A buffer of
            this object (overwritten by the next call).

        """
        routing_lengths_into(np.ascontiguousarray(positions, dtype=float),
                             np.ascontiguousarray(rotations, dtype=float), *self.routing,
                             self._lengths, self._jacobian, *self._scratch)
        return self._lengths.copy(), self._jacobian


class CableTerms:
    """
    Every cable of a scene (all its cable groups) indexed for the compiled cable pass.

    Parameters
    ----------
    groups : sequence of (CableGroup, sequence of int)
        The cable groups and their columns in the actuator order.
    n_frames : int
        Number of frames (base included).

    Attributes
    ----------
    gains, columns : (m_c,) ndarray
        Force gain and actuator column of every cable.
    frames, offsets, start, end, span_owner, point_owner : ndarray
        The routing of :attr:`CableGroup.routing`, the cables numbered across the groups.
    pairs : list of (int, int)
        Frame pairs ``(a, b)`` of the spans, one 12 x 12 stiffness block each.
    span_pair : (S,) int ndarray
        The pair of every span.
    moment_frames : list of int
        Frames carrying routing points, one 3 x 3 moment block each.
    point_slot : (P,) int ndarray
        The moment block of every point.

    """

    def __init__(self, groups, n_frames):
        """Concatenate the groups' routing; index the block of every span and point."""
        self.n_frames = int(n_frames)
        routing = [[] for _ in range(6)]
        gains, columns = [], []
        points, cables = 0, 0
        for group, group_columns in groups:
            frames, offsets, start, end, span_owner, point_owner = group.routing
            for part, value in zip(routing, (frames, offsets, start + points, end + points,
                                             span_owner + cables, point_owner + cables)):
                part.append(value)
            gains.append(group.gains)
            columns.append(np.asarray(group_columns, dtype=np.int64))
            points += frames.size
            cables += group.n_actuators
        (self.frames, self.offsets, self.start, self.end, self.span_owner,
         self.point_owner) = (
            np.ascontiguousarray(np.concatenate(part) if part else empty, dtype=empty.dtype)
            for part, empty in zip(routing, _EMPTY_ROUTING))
        self.gains = np.ascontiguousarray(np.concatenate(gains) if gains else np.zeros(0))
        self.columns = np.ascontiguousarray(np.concatenate(columns) if columns
                                            else np.zeros(0, dtype=np.int64))
        pairs = {}
        self.span_pair = np.array([
            pairs.setdefault((int(self.frames[s]), int(self.frames[e])), len(pairs))
            for s, e in zip(self.start, self.end)], dtype=np.int64)
        self.pairs = list(pairs)
        self.moment_frames = sorted({int(f) for f in self.frames})
        slot = {f: i for i, f in enumerate(self.moment_frames)}
        self.point_slot = np.array([slot[int(f)] for f in self.frames], dtype=np.int64)


_EMPTY_ROUTING = (np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros(0, dtype=np.int64),
                  np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64),
                  np.zeros(0, dtype=np.int64))
