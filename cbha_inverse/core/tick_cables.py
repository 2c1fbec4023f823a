"""
Cable part of the fused tick (:mod:`cbha_inverse.core.tick`): routing data for the kernel.

Same quantities as :class:`cbha_inverse.core.actuation.CableGroup` (``evaluate`` and the
symmetric ``load_tangent``), computed by :func:`cbha_inverse.core.tick_kernels.cable_pass` from
the group's routing points; here only the constant index arrays: which frame-pair block receives
each span's stiffness ``C P Cᵀ`` and which frame's moment block receives each point's.
"""

from cbha_inverse.core.tick_kernels import cable_pass
import numpy as np


class CableTerms:
    """
    Precomputed evaluator of one :class:`~cbha_inverse.core.actuation.CableGroup` for a tick.

    Parameters
    ----------
    group : cbha_inverse.core.actuation.CableGroup
        The cables.
    columns : sequence of int
        Their columns in the actuator order.
    n_frames : int
        Number of frames (base included).

    Attributes
    ----------
    pairs : list of (int, int)
        Frame pairs ``(a, b)`` of the spans, one 12 x 12 stiffness block each.
    moment_frames : list of int
        Frames carrying routing points, one 3 x 3 moment block each.

    """

    def __init__(self, group, columns, n_frames):
        """Precompute the routing and the block of every span and point."""
        self.n_frames = int(n_frames)
        self.columns = np.asarray(columns, dtype=np.int64)
        self.frames = np.ascontiguousarray(group.frames, dtype=np.int64)
        self.offsets = np.ascontiguousarray(group.offsets, dtype=float)
        self.start = np.ascontiguousarray(group.segment_start, dtype=np.int64)
        self.end = np.ascontiguousarray(group.segment_end, dtype=np.int64)
        self.span_owner = np.ascontiguousarray(group._segment_owner, dtype=np.int64)
        self.point_owner = np.ascontiguousarray(group._point_owner, dtype=np.int64)
        pairs = {}
        self.span_pair = np.array([
            pairs.setdefault((int(self.frames[s]), int(self.frames[e])), len(pairs))
            for s, e in zip(self.start, self.end)], dtype=np.int64)
        self.pairs = list(pairs)
        self.moment_frames = sorted({int(f) for f in self.frames})
        slot = {f: i for i, f in enumerate(self.moment_frames)}
        self.point_slot = np.array([slot[int(f)] for f in self.frames], dtype=np.int64)

    def evaluate(self, positions, rotations, actuation, rhs, pair_values, moment_values):
        """
        Add the cable columns and loads to ``rhs``; write the stiffness blocks.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations.
        actuation : (m,) ndarray  [N]
            All actuators (the cable tensions are taken at :attr:`columns`).
        rhs : (6n, m + 1) ndarray
            C-contiguous; residual (column 0) and ``J_aᵀ`` (columns ``1 + j``), added to.
        pair_values : (P * 144,) ndarray
            Receives the span stiffness blocks summed per frame pair (12 x 12 each).
        moment_values : (F * 9,) ndarray
            Receives the point moment blocks summed per frame (3 x 3 each).

        """
        cable_pass(positions, rotations, actuation, self.frames, self.offsets, self.start,
                   self.end, self.span_owner, self.point_owner, self.columns,
                   self.span_pair, self.point_slot, rhs, pair_values.reshape(-1, 12, 12),
                   moment_values.reshape(-1, 3, 3))
