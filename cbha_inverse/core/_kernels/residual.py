"""
Compiled convergence measures of the static solver's residual (paper eq. 9).

:func:`residual_measures` adds the dead loads to the residual of an evaluation and returns, in
one loop, the norms :mod:`cbha_inverse.core.statics` tests convergence with.
"""

import math

import numba


@numba.njit(cache=True)
def residual_measures(rhs, actuation, dead, extra, load_factor, length, floor, tolerance, out,
                      frame_max):
    """
    Write the residual ``r = f(q) + lam (f_dead + J_aᵀ λ + f_extra)`` and return its measures.

    Moments are divided by the chain length (``r_scaled`` in N) for the relative measures.

    Parameters
    ----------
    rhs : (6n, m + 1) ndarray
        A linearisation pass at the actuation ``lam λ``, without dead loads: column 0 is
        ``f(q) + J_aᵀ (lam λ)``, columns 1..m are ``J_aᵀ``.
    actuation : (m,) ndarray  [N, Pa]
        ``lam λ``.
    dead : (6n,) ndarray  [N, N*m]
        ``f_dead``.
    extra : (6n,) ndarray  [N, N*m]
        ``f_extra`` (user follower loads at the state; zeros without).
    load_factor : float
        ``lam``.
    length : float  [m]
        Chain length.
    floor : (n,) ndarray  [N]
        Round-off level of the scaled internal wrench at each of frames 1..n.
    tolerance : float
        Relative tolerance of the convergence test.
    out : (6n,) ndarray
        Receives ``r``.
    frame_max : (n,) ndarray
        Receives ``max |r_scaled|`` of each frame.

    Returns
    -------
    measure : float  [N]
        ``max |r_scaled|`` (``inf`` if any component is not finite).
    merit : float  [N]
        Euclidean norm of the part of ``|r_scaled|`` above each frame's floor (the line search's
        merit).
    scaled_norm : float  [N]
        ``|r_scaled|_2``.
    norm : float  [N, N*m]
        ``|r|_2``.
    load_scale : float  [N]
        Largest scaled component of the applied loads and of the internal wrenches.
    within_roundoff : bool
        Whether every frame's ``max |r_scaled|`` is within ``tolerance * load_scale`` plus its
        floor (the residual part of the round-off limited test of
        :mod:`cbha_inverse.core.statics`).

    """
    size, width = rhs.shape
    measure, merit, squares, squares_raw, load_scale = 0.0, 0.0, 0.0, 0.0, 0.0
    finite = True
    for row in range(size):
        frame = row // 6
        if row % 6 == 0:
            frame_max[frame] = 0.0
        load = load_factor * (dead[row] + extra[row])
        for j in range(width - 1):
            load += rhs[row, 1 + j] * actuation[j]
        r = rhs[row, 0] + load_factor * (dead[row] + extra[row])
        out[row] = r
        if not math.isfinite(r):
            finite = False
        weight = 1.0 if row % 6 < 3 else 1.0 / length
        scaled = abs(r * weight)
        frame_max[frame] = max(frame_max[frame], scaled)
        measure = max(measure, scaled)
        above = max(scaled - floor[frame], 0.0)
        merit += above * above
        squares += scaled * scaled
        squares_raw += r * r
        load_scale = max(load_scale, abs(load * weight), abs((r - load) * weight))
    if not finite:
        return math.inf, math.inf, math.inf, math.inf, load_scale, False
    bound = tolerance * load_scale
    within = True
    for frame in range(frame_max.size):
        if frame_max[frame] > bound + floor[frame]:
            within = False
    return (measure, math.sqrt(merit), math.sqrt(squares), math.sqrt(squares_raw), load_scale,
            within)
