"""
Cable part of the fused tick (:mod:`cbha_inverse.core.tick`): columns, loads, load stiffness.

Same quantities as :class:`cbha_inverse.core.actuation.CableGroup` (``evaluate`` and the
symmetric ``load_tangent``), from its routing data, in a fixed number of batched calls: the span
vectors by one constant difference matrix, the point wrenches scattered to (frame, cable) by one
matrix product, and the span stiffness blocks ``C P Cᵀ`` (``P = λ/ℓ (I - u uᵀ)``,
``C = [I; r_s^; -I; -r_e^]``) summed per frame pair by another.
"""

from cbha_inverse.core.se3 import HAT_BASIS
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

    """

    def __init__(self, group, columns, n_frames):
        """Precompute the routing, scatter and summation matrices."""
        self.n_frames = int(n_frames)
        self.columns = np.asarray(columns, dtype=int)
        self.contiguous = bool(np.all(np.diff(self.columns) == 1))
        self.frames = group.frames
        self.offsets = group.offsets[:, :, None]
        n_points = self.frames.size
        start, end = group.segment_start, group.segment_end
        n_spans = start.size
        self.start, self.end = start, end
        self.span_matrix = np.zeros((n_spans, n_points))
        self.span_matrix[np.arange(n_spans), end] = 1.0
        self.span_matrix[np.arange(n_spans), start] -= 1.0
        self.point_force = group._point_force
        self.segment_owner = group._segment_owner
        self.point_owner = group._point_owner
        m_c = len(group.cables)
        self.m = m_c
        # scatter of point wrenches into (mobile frame, cable)
        self.scatter = np.zeros(((n_frames - 1) * m_c, n_points))
        mobile = self.frames > 0
        self.scatter[((self.frames - 1) * m_c + self.point_owner)[mobile],
                     np.arange(n_points)[mobile]] = 1.0
        # span blocks summed per frame pair
        pairs = {}
        pair_of_span = np.empty(n_spans, dtype=int)
        for s in range(n_spans):
            key = (int(self.frames[start[s]]), int(self.frames[end[s]]))
            pair_of_span[s] = pairs.setdefault(key, len(pairs))
        self.pairs = list(pairs)
        self.pair_sum = np.zeros((len(pairs), n_spans))
        self.pair_sum[pair_of_span, np.arange(n_spans)] = 1.0
        frames_used = sorted({int(f) for f in self.frames})
        self.moment_frames = frames_used
        where = {f: i for i, f in enumerate(frames_used)}
        self.frame_sum = np.zeros((len(frames_used), n_points))
        self.frame_sum[[where[int(f)] for f in self.frames], np.arange(n_points)] = 1.0
        self.c = np.zeros((n_spans, 12, 3))
        self.c[:, 0:3] = np.eye(3)
        self.c[:, 6:9] = -np.eye(3)
        self.hats = np.zeros((n_points, 3, 3))
        self.wrench = np.empty((n_points, 6))

    def evaluate(self, positions, rotations, actuation, rhs, pair_values, moment_values,
                 accumulate):
        """
        Write the cable columns, their loads and their load stiffness blocks.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations.
        actuation : (m,) ndarray
            All actuators (the cable tensions are taken at :attr:`columns`).
        rhs : (6n, m + 1) ndarray
            C-contiguous; residual (column 0, the cable loads are added) and ``J_aᵀ`` (columns
            ``1 + j``).
        pair_values : (P * 144,) ndarray
            Receives the span stiffness blocks summed per frame pair (12 x 12 each).
        moment_values : (F * 9,) ndarray
            Receives the point moment blocks summed per frame (3 x 3 each).
        accumulate : bool
            Add to the columns of ``rhs`` instead of overwriting them.

        """
        cab = self
        n = self.n_frames - 1
        levers = np.matmul(rotations[cab.frames], cab.offsets)[:, :, 0]
        points = positions[cab.frames] + levers
        spans = cab.span_matrix @ points
        lengths = np.sqrt(np.einsum('si,si->s', spans, spans))
        units = spans / lengths[:, None]
        forces = cab.point_force @ units
        hats = cab.hats
        np.matmul(levers, HAT_BASIS, out=hats.reshape(-1, 9))
        wrench = cab.wrench
        wrench[:, :3] = forces
        np.matmul(hats, forces[:, :, None], out=wrench[:, 3:, None])
        cols = (cab.scatter @ wrench).reshape(n, cab.m, 6)
        tension = actuation[cab.columns]
        by_frame = rhs.reshape(n, 6, -1)
        if cab.contiguous:
            target = by_frame[:, :, 1 + cab.columns[0]:1 + cab.columns[-1] + 1]
            if accumulate:
                target += cols.transpose(0, 2, 1)
            else:
                target[...] = cols.transpose(0, 2, 1)
        else:
            rhs[:, 1 + cab.columns] += cols.transpose(0, 2, 1).reshape(6 * n, cab.m)
        rhs[:, 0] += np.matmul(tension, cols).reshape(-1)
        # load stiffness: per span t/l (I - u u^T) through C = [I; r_s^; -I; -r_e^]
        scale = tension[cab.segment_owner] / lengths
        proj = -(scale[:, None, None] * units[:, :, None]) * units[:, None, :]
        proj.reshape(-1, 9)[:, ::4] += scale[:, None]
        c = cab.c
        c[:, 3:6] = hats[cab.start]
        np.negative(hats[cab.end], out=c[:, 9:12])
        span_blocks = np.matmul(np.matmul(c, proj), c.transpose(0, 2, 1))
        np.matmul(cab.pair_sum, span_blocks.reshape(-1, 144),
                  out=pair_values.reshape(-1, 144))
        # point moments (F·r) I - sym(r Fᵀ), summed per frame: with A = Σ r Fᵀ it is tr(A) I - A
        # (the assembly symmetrises)
        point_forces = forces * tension[cab.point_owner][:, None]
        moment = moment_values.reshape(-1, 9)
        np.matmul(cab.frame_sum, (levers[:, :, None] * point_forces[:, None, :]).reshape(-1, 9),
                  out=moment)
        trace = moment[:, ::4].sum(axis=1)
        np.negative(moment, out=moment)
        moment[:, ::4] += trace[:, None]
