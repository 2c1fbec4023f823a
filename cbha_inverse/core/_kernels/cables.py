"""
Compiled cable terms of the equilibrium (paper eq. 9): columns of ``J_aᵀ``, loads, load stiffness.

:func:`cable_pass` (numba) computes the cable columns, their loads, the span stiffness
``C P Cᵀ`` (``P = g λ/ℓ (I - u uᵀ)``, ``C = [I; r_s^; -I; -r_e^]``) summed per frame pair and the
exact point moments ``tr(A) I - A``, ``A = Σ r (λ F)ᵀ``, for the routing data of
:class:`cbha_inverse.core.actuation.cables.CableTerms`. A cable's gain ``g`` (calibration; 1 for
the ideal cable) scales its force per unit tension ``F``: column, load and load stiffness alike.
:func:`routing_lengths` gives the routed lengths and their gradient from the same routing
geometry (the passive cables of string potentiometers, :mod:`cbha_inverse.core.sensors`).
"""

import math

from cbha_inverse.core._kernels.so3 import hat_into
import numba
import numpy as np

# cable span blocks (see cable_pass): base matrix and sign of each 3-row block of C, and the
# slot of the summed product B_x P B_y^T (x >= y; x, y = 0: I, 1: S, 2: T)
_CABLE_BASE = np.array([0, 1, 0, 2])
_CABLE_SIGN = np.array([1.0, 1.0, -1.0, -1.0])
_CABLE_PRODUCT = np.array([[0, -1, -1], [1, 3, -1], [2, 4, 5]])


@numba.njit(cache=True)
def point_wrench(force, lever):
    """
    Return the wrench ``(f, r × f)`` of a force at a lever from its frame's origin.

    Parameters
    ----------
    force : (3,) ndarray  [N]
        The force.
    lever : (3,) ndarray  [m]
        Its point of application relative to the frame's origin.

    Returns
    -------
    tuple of 6 float  [N, N*m]

    """
    f, r = force, lever
    return (f[0], f[1], f[2], r[1] * f[2] - r[2] * f[1], r[2] * f[0] - r[0] * f[2],
            r[0] * f[1] - r[1] * f[0])


@numba.njit(cache=True)
def routing_spans(positions, rotations, frames, offsets, span_start, span_end):
    """
    Return the routing points of cables (or string potentiometers) and their straight spans.

    Parameters
    ----------
    positions : (n + 1, 3) ndarray  [m]
        Frame origins.
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations.
    frames : (P,) int ndarray
        Frame of every routing point.
    offsets : (P, 3) ndarray  [m]
        Routing points in their frame's axes.
    span_start, span_end : (S,) int ndarray
        Points of every straight span.

    Returns
    -------
    levers : (P, 3) ndarray  [m]
        ``R_f o`` of every point.
    points : (P, 3) ndarray  [m]
        World positions of the points.
    units : (S, 3) ndarray
        Unit vector of every span, from its start point to its end point.
    lengths : (S,) ndarray  [m]
        Length of every span.

    """
    levers = np.empty((frames.size, 3))
    points = np.empty((frames.size, 3))
    units = np.empty((span_start.size, 3))
    lengths = np.empty(span_start.size)
    routing_spans_into(positions, rotations, frames, offsets, span_start, span_end, levers,
                       points, units, lengths)
    return levers, points, units, lengths


@numba.njit(cache=True)
def routing_spans_into(positions, rotations, frames, offsets, span_start, span_end, levers,
                       points, units, lengths):
    """:func:`routing_spans` into given ``levers``, ``points``, ``units``, ``lengths``."""
    for p in range(frames.size):
        rot = rotations[frames[p]]
        for i in range(3):
            levers[p, i] = rot[i, 0] * offsets[p, 0] + rot[i, 1] * offsets[p, 1] + rot[
                i, 2] * offsets[p, 2]
            points[p, i] = positions[frames[p], i] + levers[p, i]
    for s in range(span_start.size):
        for i in range(3):
            units[s, i] = points[span_end[s], i] - points[span_start[s], i]
        length = math.sqrt(units[s, 0] ** 2 + units[s, 1] ** 2 + units[s, 2] ** 2)
        lengths[s] = length
        for i in range(3):
            units[s, i] /= length


@numba.njit(cache=True)
def routing_forces(units, gains, span_start, span_end, span_owner, n_points):
    """
    Return the force per unit tension on every routing point: ``-gain d(length)/d(point)``.

    A span pulls its start point toward its end and the end point back.

    Parameters
    ----------
    units : (S, 3) ndarray
        Span unit vectors (:func:`routing_spans`).
    gains : (c,) ndarray  [-]
        Factor of every cable on its force (1 for the bare length gradient).
    span_start, span_end, span_owner : (S,) int ndarray
        Points and cable of every span.
    n_points : int
        Number of routing points.

    Returns
    -------
    (P, 3) ndarray  [-]

    """
    forces = np.empty((n_points, 3))
    routing_forces_into(units, gains, span_start, span_end, span_owner, forces)
    return forces


@numba.njit(cache=True)
def routing_forces_into(units, gains, span_start, span_end, span_owner, forces):
    """:func:`routing_forces` into a given ``(P, 3)`` array ``forces`` (overwritten)."""
    forces[:, :] = 0.0
    for s in range(span_start.size):
        gain = gains[span_owner[s]]
        for i in range(3):
            forces[span_start[s], i] += gain * units[s, i]
            forces[span_end[s], i] -= gain * units[s, i]


@numba.njit(cache=True)
def routing_lengths(positions, rotations, frames, offsets, span_start, span_end, span_owner,
                    point_owner, n_cables, jacobian):
    """
    Return the routed length of every cable and write its gradient ``d(length)/dq``.

    The length is the sum of the straight spans (:func:`routing_spans`); its gradient, in the
    retract increments ``dq = (dx_f, dθ_f)`` of frames 1..n, is minus the cable's column of
    ``J_aᵀ`` at unit gain (:func:`cable_pass`): the routing geometry is the same.

    Parameters
    ----------
    positions, rotations, frames, offsets, span_start, span_end
        As :func:`routing_spans`.
    span_owner, point_owner : (S,), (P,) int ndarray
        Cable (0..c - 1) of every span and point.
    n_cables : int
        Number of cables ``c``.
    jacobian : (c, 6n) ndarray
        Receives ``d(length)/dq`` [-, m/rad] (overwritten).

    Returns
    -------
    (c,) ndarray  [m]

    """
    n_points, n_spans = frames.size, span_start.size
    lengths = np.empty(n_cables)
    routing_lengths_into(positions, rotations, frames, offsets, span_start, span_end,
                         span_owner, point_owner, lengths, jacobian,
                         np.empty(routing_work_size(n_points, n_spans, n_cables)))
    return lengths


@numba.njit(cache=True)
def routing_work_size(n_points, n_spans, n_cables):
    """Return the length of the workspace of :func:`routing_lengths_into`."""
    return 9 * n_points + 4 * n_spans + n_cables


@numba.njit(cache=True)
def routing_lengths_into(positions, rotations, frames, offsets, span_start, span_end,
                         span_owner, point_owner, lengths, jacobian, work):
    """:func:`routing_lengths` into ``lengths`` (c,), ``work``: :func:`routing_work_size`."""
    n_points, n_spans = frames.size, span_start.size
    end = 3 * n_points
    levers = work[:end].reshape((n_points, 3))
    points = work[end:2 * end].reshape((n_points, 3))
    forces = work[2 * end:3 * end].reshape((n_points, 3))
    units = work[3 * end:3 * end + 3 * n_spans].reshape((n_spans, 3))
    span_lengths = work[3 * end + 3 * n_spans:3 * end + 4 * n_spans]
    unit_gains = work[3 * end + 4 * n_spans:]
    unit_gains[:] = 1.0
    routing_spans_into(positions, rotations, frames, offsets, span_start, span_end, levers,
                       points, units, span_lengths)
    routing_forces_into(units, unit_gains, span_start, span_end, span_owner, forces)
    lengths[:] = 0.0
    for s in range(n_spans):
        lengths[span_owner[s]] += span_lengths[s]
    jacobian[:, :] = 0.0
    for p in range(n_points):
        if frames[p] > 0:
            wrench = point_wrench(forces[p], levers[p])
            row = point_owner[p]
            col = 6 * (frames[p] - 1)
            for i in range(6):
                jacobian[row, col + i] -= wrench[i]


@numba.njit(cache=True)
def cable_pass(positions, rotations, actuation, gains, frames, offsets, span_start, span_end,
               span_owner, point_owner, columns, span_pair, point_slot, rhs, pair_values,
               moment_values):
    """
    Add one cable group's columns and loads to ``rhs``; write its stiffness blocks.

    The routing geometry is :func:`routing_spans` and :func:`routing_forces` (shared with the
    string potentiometers' :func:`routing_lengths`). The span blocks are symmetric; the point
    moment blocks are the exact (non-symmetric) load stiffness, whose symmetric part the control
    tick keeps.

    Parameters
    ----------
    positions : (n + 1, 3) ndarray  [m]
        Frame origins.
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations.
    actuation : (m,) ndarray  [N]
        All actuators (the tensions are at ``columns``).
    gains : (m_c,) ndarray  [-]
        Factor of every cable on its force per unit tension (its column, load and load
        stiffness; a scene's ``calibration.actuator_gain``, 1 = the ideal cable).
    frames : (P,) int ndarray
        Frame of every routing point.
    offsets : (P, 3) ndarray  [m]
        Routing points in their frame's axes.
    span_start, span_end : (S,) int ndarray
        Points of every straight span (consecutive points of one cable).
    span_owner, point_owner : (S,), (P,) int ndarray
        Cable (0..m_c - 1) of every span and point.
    columns : (m_c,) int ndarray
        Actuator column of every cable.
    span_pair : (S,) int ndarray
        Frame-pair block that receives each span's stiffness.
    point_slot : (P,) int ndarray
        Moment block (one per frame used) that receives each point's moment stiffness.
    rhs : (6n, m + 1) ndarray
        Column 0 (residual) and the cables' ``J_aᵀ`` columns are added to.
    pair_values : (n_pairs, 12, 12) ndarray
        Receives the span blocks summed per frame pair.
    moment_values : (n_slots, 3, 3) ndarray
        Receives the point moment blocks summed per frame.

    """
    work = np.empty(cable_work_size(frames.size, span_start.size, pair_values.shape[0]))
    cable_pass_into(positions, rotations, actuation, gains, frames, offsets, span_start, span_end,
                    span_owner, point_owner, columns, span_pair, point_slot, rhs, pair_values,
                    moment_values, work)


@numba.njit(cache=True)
def cable_work_size(n_points, n_spans, n_pairs):
    """Return the length of the workspace of :func:`cable_pass_into`."""
    return 9 * n_points + 4 * n_spans + 54 * n_pairs + 45


@numba.njit(cache=True)
def cable_pass_into(positions, rotations, actuation, gains, frames, offsets, span_start,
                    span_end, span_owner, point_owner, columns, span_pair, point_slot, rhs,
                    pair_values, moment_values, work):
    """:func:`cable_pass` with its workspace given, ``work`` (:func:`cable_work_size`,)."""
    n_points = frames.size
    n_spans = span_start.size
    n_pairs = pair_values.shape[0]
    end = 3 * n_points
    levers = work[:end].reshape((n_points, 3))
    points = work[end:2 * end].reshape((n_points, 3))
    forces = work[2 * end:3 * end].reshape((n_points, 3))
    used = 3 * end
    units = work[used:used + 3 * n_spans].reshape((n_spans, 3))
    lengths = work[used + 3 * n_spans:used + 4 * n_spans]
    used += 4 * n_spans
    sums = work[used:used + 54 * n_pairs].reshape((n_pairs, 6, 3, 3))
    used += 54 * n_pairs
    proj = work[used:used + 9].reshape((3, 3))
    s_hat = work[used + 9:used + 18].reshape((3, 3))
    t_hat = work[used + 18:used + 27].reshape((3, 3))
    sp = work[used + 27:used + 36].reshape((3, 3))
    tp = work[used + 36:used + 45].reshape((3, 3))
    routing_spans_into(positions, rotations, frames, offsets, span_start, span_end, levers,
                       points, units, lengths)
    routing_forces_into(units, gains, span_start, span_end, span_owner, forces)
    moment_values[:, :, :] = 0.0
    for p in range(n_points):
        f, r = forces[p], levers[p]
        tension = actuation[columns[point_owner[p]]]
        if frames[p] > 0:
            row = 6 * (frames[p] - 1)
            col = 1 + columns[point_owner[p]]
            wrench = point_wrench(f, r)
            for i in range(6):
                rhs[row + i, col] += wrench[i]
                rhs[row + i, 0] += tension * wrench[i]
        # A = sum r (t F)^T per frame; the block is tr(A) I - A
        block = moment_values[point_slot[p]]
        for i in range(3):
            for j in range(3):
                block[i, j] -= tension * r[i] * f[j]
        trace = tension * (r[0] * f[0] + r[1] * f[1] + r[2] * f[2])
        for i in range(3):
            block[i, i] += trace
    # C P C^T with C = [I; S; -I; -T] (S, T the hats of the start and end levers): block (i, j)
    # is sign_i sign_j B_i P B_j^T with B = (I, S, I, T), sign = (1, 1, -1, -1); only the six
    # products P, SP, TP, SPS^T, TPS^T, TPT^T are summed per frame pair, then expanded
    sums[:, :, :, :] = 0.0
    for s in range(n_spans):
        scale = gains[span_owner[s]] * actuation[columns[span_owner[s]]] / lengths[s]
        u = units[s]
        for i in range(3):
            for j in range(3):
                proj[i, j] = -scale * u[i] * u[j]
            proj[i, i] += scale
        hat_into(levers[span_start[s]], s_hat)
        hat_into(levers[span_end[s]], t_hat)
        for i in range(3):
            for j in range(3):
                sp[i, j] = s_hat[i, 0] * proj[0, j] + s_hat[i, 1] * proj[1, j] + s_hat[
                    i, 2] * proj[2, j]
                tp[i, j] = t_hat[i, 0] * proj[0, j] + t_hat[i, 1] * proj[1, j] + t_hat[
                    i, 2] * proj[2, j]
        acc = sums[span_pair[s]]
        for i in range(3):
            for j in range(3):
                acc[0, i, j] += proj[i, j]
                acc[1, i, j] += sp[i, j]
                acc[2, i, j] += tp[i, j]
                acc[3, i, j] += sp[i, 0] * s_hat[j, 0] + sp[i, 1] * s_hat[j, 1] + sp[
                    i, 2] * s_hat[j, 2]
                acc[4, i, j] += tp[i, 0] * s_hat[j, 0] + tp[i, 1] * s_hat[j, 1] + tp[
                    i, 2] * s_hat[j, 2]
                acc[5, i, j] += tp[i, 0] * t_hat[j, 0] + tp[i, 1] * t_hat[j, 1] + tp[
                    i, 2] * t_hat[j, 2]
    for pair in range(n_pairs):
        out = pair_values[pair]
        acc = sums[pair]
        for bi in range(4):
            for bj in range(4):
                x, y = _CABLE_BASE[bi], _CABLE_BASE[bj]
                sign = _CABLE_SIGN[bi] * _CABLE_SIGN[bj]
                for i in range(3):
                    for j in range(3):
                        value = (acc[_CABLE_PRODUCT[x, y], i, j] if x >= y
                                 else acc[_CABLE_PRODUCT[y, x], j, i])
                        out[3 * bi + i, 3 * bj + j] = sign * value
