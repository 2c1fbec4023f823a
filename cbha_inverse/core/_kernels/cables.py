"""
Compiled cable terms of the equilibrium (paper eq. 9): columns of ``J_aᵀ``, loads, load stiffness.

:func:`cable_pass` computes the cable columns, their loads, the span stiffness
``C P Cᵀ`` (``P = g λ/ℓ (I - u uᵀ)``, ``C = [I; r_s^; -I; -r_e^]``) summed per frame pair and the
exact point moments ``tr(A) I - A``, ``A = Σ r (λ F)ᵀ``, for the routing data of
:class:`cbha_inverse.core.actuation.cables.CableTerms` (every cable of a scene, whatever its
group). A cable's gain ``g`` (calibration; 1 for the ideal cable) scales its force per unit
tension ``F``: column, load and load stiffness alike.
:func:`routing_lengths_into` gives the routed lengths and their gradient from the same routing
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


@numba.njit(cache=True, inline='always')
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
def routing_lengths_into(positions, rotations, frames, offsets, span_start, span_end,
                         span_owner, point_owner, lengths, jacobian, levers, points, forces,
                         units, span_lengths, unit_gains):
    """
    Write the routed length of every cable and its gradient ``d(length)/dq``.

    The length is the sum of the straight spans (:func:`routing_spans_into`); its gradient, in
    the retract increments ``dq = (dx_f, dθ_f)`` of frames 1..n, is minus the cable's column of
    ``J_aᵀ`` at unit gain (:func:`cable_pass`): the routing geometry is the same.

    Parameters
    ----------
    positions, rotations, frames, offsets, span_start, span_end
        As :func:`routing_spans_into`.
    span_owner, point_owner : (S,), (P,) int ndarray
        Cable (0..c - 1) of every span and point.
    lengths : (c,) ndarray  [m]
        Receives the lengths.
    jacobian : (c, 6n) ndarray
        Receives ``d(length)/dq`` [-, m/rad] (overwritten).
    levers, points, forces : (P, 3) ndarray
        Scratch of :func:`routing_spans_into` and :func:`routing_forces_into`.
    units : (S, 3) ndarray
        Scratch: the span unit vectors.
    span_lengths : (S,) ndarray
        Scratch: the span lengths.
    unit_gains : (c,) ndarray
        Ones (the bare length gradient).

    """
    routing_spans_into(positions, rotations, frames, offsets, span_start, span_end, levers,
                       points, units, span_lengths)
    routing_forces_into(units, unit_gains, span_start, span_end, span_owner, forces)
    lengths[:] = 0.0
    for s in range(span_start.size):
        lengths[span_owner[s]] += span_lengths[s]
    jacobian[:, :] = 0.0
    for p in range(frames.size):
        if frames[p] > 0:
            wrench = point_wrench(forces[p], levers[p])
            row = point_owner[p]
            col = 6 * (frames[p] - 1)
            for i in range(6):
                jacobian[row, col + i] -= wrench[i]


@numba.njit(cache=True)
def cable_pass(system, positions, rotations, actuation):
    """
    Add the cables' columns and loads to ``system.rhs``; write their stiffness blocks.

    The routing geometry is :func:`routing_spans_into` and :func:`routing_forces_into` (shared
    with the string potentiometers' :func:`routing_lengths_into`). Each routing point on a moving
    frame adds its wrench per unit tension to its cable's column of ``J_aᵀ`` and, times the
    tension, to the residual; :func:`add_point_moments` and :func:`add_span_stiffness` give the
    exact load stiffness, written into ``system.values`` after the link blocks: the span blocks
    summed per frame pair (12 x 12, symmetric), then the point moment blocks summed per frame
    (3 x 3, not symmetric; the control tick keeps their symmetric part).

    Parameters
    ----------
    system : EquilibriumRecord
        The chain's terms and buffers (:mod:`cbha_inverse.core._kernels.evaluation`): the
        cables' routing, gains and actuator columns, the scratch arrays; ``rhs`` is added to.
    positions : (n + 1, 3) ndarray  [m]
        Frame origins.
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations.
    actuation : (m,) ndarray  [N]
        All actuators (the tensions are at the cables' columns).

    """
    frames, gains, columns = system.cable_frames, system.cable_gains, system.cable_columns
    levers, forces = system.cable_levers, system.cable_forces
    routing_spans_into(positions, rotations, frames, system.cable_offsets, system.span_start,
                       system.span_end, levers, system.cable_points, system.span_units,
                       system.span_lengths)
    routing_forces_into(system.span_units, gains, system.span_start, system.span_end,
                        system.span_owner, forces)
    rhs, point_owner = system.rhs, system.point_owner
    for p in range(frames.size):
        if frames[p] > 0:
            cable = point_owner[p]
            tension = actuation[columns[cable]]
            row = 6 * (frames[p] - 1)
            wrench = point_wrench(forces[p], levers[p])
            for i in range(6):
                rhs[row + i, 1 + columns[cable]] += wrench[i]
                rhs[row + i, 0] += tension * wrench[i]
    n_pairs, n_moments = system.pair_sums.shape[0], system.moment_count
    pair_values = system.values[system.pair_start:system.pair_start + 144 * n_pairs]
    moment_values = system.values[system.moment_start:system.moment_start + 9 * n_moments]
    add_point_moments(actuation, columns, point_owner, system.point_slot, forces, levers,
                      moment_values.reshape((n_moments, 3, 3)))
    add_span_stiffness(system, actuation, pair_values.reshape((n_pairs, 12, 12)))


@numba.njit(cache=True)
def add_point_moments(actuation, columns, point_owner, point_slot, forces, levers, blocks):
    """
    Write the exact moment stiffness of the routing points, summed per frame.

    A point at lever ``r`` from its frame's origin, pulled by ``t F``, gives the moment
    ``r × t F``; turning the frame turns ``r`` and ``F`` alike, so ``-d M / dθ = tr(A) I - A``,
    ``A = Σ r (t F)ᵀ`` over the frame's points.

    Parameters
    ----------
    actuation : (m,) ndarray  [N]
        All actuators.
    columns : (m_c,) int ndarray
        Actuator column of every cable.
    point_owner, point_slot : (P,) int ndarray
        Cable and moment block of every point.
    forces, levers : (P, 3) ndarray  [-, m]
        Force per unit tension and lever of every point.
    blocks : (F, 3, 3) ndarray  [N*m/rad]
        Receives the blocks.

    """
    blocks[:, :, :] = 0.0
    for p in range(forces.shape[0]):
        tension = actuation[columns[point_owner[p]]]
        block = blocks[point_slot[p]]
        for i in range(3):
            for j in range(3):
                block[i, j] -= tension * levers[p, i] * forces[p, j]
        trace = tension * (levers[p, 0] * forces[p, 0] + levers[p, 1] * forces[p, 1]
                           + levers[p, 2] * forces[p, 2])
        for i in range(3):
            block[i, i] += trace


@numba.njit(cache=True)
def add_span_stiffness(system, actuation, blocks):
    """
    Write the stiffness of the cables' straight spans, summed per frame pair.

    A span of length ``ℓ`` and unit vector ``u`` under tension ``t`` (gain ``g``) between points
    at levers ``s`` (frame ``a``) and ``e`` (frame ``b``) has the stiffness ``C P Cᵀ``,
    ``P = g t / ℓ (I - u uᵀ)``, ``C = [I; s^; -I; -e^]`` over the increments of both frames.
    Block ``(i, j)`` of ``C P Cᵀ`` is ``sign_i sign_j B_i P B_jᵀ`` with ``B = (I, S, I, T)``,
    ``sign = (1, 1, -1, -1)`` (``S``, ``T`` the hats of ``s`` and ``e``): the six products ``P``,
    ``S P``, ``T P``, ``S P Sᵀ``, ``T P Sᵀ``, ``T P Tᵀ`` are summed per frame pair
    (``system.pair_sums``), then expanded.

    Parameters
    ----------
    system : EquilibriumRecord
        The cables' routing and scratch (``span_units`` and ``span_lengths`` written by the
        routing, ``cable_levers``).
    actuation : (m,) ndarray  [N]
        All actuators.
    blocks : (n_pairs, 12, 12) ndarray
        Receives the blocks (rows and columns: frame ``a``'s increments, then frame ``b``'s).

    """
    sums, projection = system.pair_sums, system.span_projection
    s_hat, t_hat = system.start_hat, system.end_hat
    sp, tp = system.start_product, system.end_product
    units, lengths, levers = system.span_units, system.span_lengths, system.cable_levers
    span_owner, columns, gains = system.span_owner, system.cable_columns, system.cable_gains
    sums[:, :, :, :] = 0.0
    for s in range(units.shape[0]):
        scale = gains[span_owner[s]] * actuation[columns[span_owner[s]]] / lengths[s]
        for i in range(3):
            for j in range(3):
                projection[i, j] = -scale * units[s, i] * units[s, j]
            projection[i, i] += scale
        hat_into(levers[system.span_start[s]], s_hat)
        hat_into(levers[system.span_end[s]], t_hat)
        for i in range(3):
            for j in range(3):
                sp[i, j] = (s_hat[i, 0] * projection[0, j] + s_hat[i, 1] * projection[1, j]
                            + s_hat[i, 2] * projection[2, j])
                tp[i, j] = (t_hat[i, 0] * projection[0, j] + t_hat[i, 1] * projection[1, j]
                            + t_hat[i, 2] * projection[2, j])
        acc = sums[system.span_pair[s]]
        for i in range(3):
            for j in range(3):
                acc[0, i, j] += projection[i, j]
                acc[1, i, j] += sp[i, j]
                acc[2, i, j] += tp[i, j]
                acc[3, i, j] += (sp[i, 0] * s_hat[j, 0] + sp[i, 1] * s_hat[j, 1]
                                 + sp[i, 2] * s_hat[j, 2])
                acc[4, i, j] += (tp[i, 0] * s_hat[j, 0] + tp[i, 1] * s_hat[j, 1]
                                 + tp[i, 2] * s_hat[j, 2])
                acc[5, i, j] += (tp[i, 0] * t_hat[j, 0] + tp[i, 1] * t_hat[j, 1]
                                 + tp[i, 2] * t_hat[j, 2])
    for pair in range(blocks.shape[0]):
        out = blocks[pair]
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
