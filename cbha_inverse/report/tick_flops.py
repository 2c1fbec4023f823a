"""
The arithmetic of one control tick, counted from its shapes, and this machine's rate for it.

:func:`tick_flops` counts the floating-point operations of a tick that linearises (the kernels of
:func:`cbha_inverse.core._kernels.tick.linearise_tick` and
:func:`~cbha_inverse.core._kernels.tick.solve_tick`), loop by loop from the kernels: a multiply
and an add are 2 flops, a division, square root or trigonometric call 1. Only the arithmetic is
counted (no copies, no index arithmetic); the active-set QP is counted for one iteration, its
usual count on a tracked target. :func:`measured_flop_rate` times the compiled multiply-add
chains of :mod:`cbha_inverse.core._kernels.flop_rate`; ``flops / rate`` is the tick's arithmetic
bound, the time it would take if it did nothing but its arithmetic at that rate
(``cbha_bench_inverse`` prints the measured tick over it).
"""

import time
from typing import NamedTuple

from cbha_inverse.core._kernels.flop_rate import multiply_add_chains

# flops of one link in links.link_pass, the tick's link pass (loops of the kernels): the
# deformation, Jl⁻¹, the local wrench and B^T K, the stress terms, the local tangent and its
# symmetric part, the lower blocks of the world tangent E^T R M R^T E, the symmetric part of the
# geometric terms ...
_LINK_BASE = 1152
# ... per condensed cavity column (its wrench, G0 + H δ, and load stiffness p H) ...
_LINK_PER_CAVITY = 156
# ... and per wrench column (rotation to world axes, gathering onto the two frames)
_LINK_PER_COLUMN = 54
# the lower triangle of a link's symmetric block added into the block band, and for the first
# link, whose base-frame rows are left out
_LINK_BAND = 78
_FIRST_LINK_BAND = 21
# cables.cable_pass: per routing point (lever, point, force, wrench, moment block) and per span
# (unit vector, force, projector, the six summed 3 x 3 products)
_CABLE_PER_POINT = 75
_CABLE_PER_SPAN = 330
# one frame of the retraction (rotation exponential and product, position update)
_RETRACT_PER_FRAME = 90


class TickShapes(NamedTuple):
    """
    The sizes that fix a tick's arithmetic.

    Attributes
    ----------
    n : int
        Links (``N = 6 n`` unknowns).
    m : int
        Actuators.
    k : int
        Effectors.
    block_width : int
        Blocks of the tangent below its diagonal (``B``).
    cavities : int
        Nonzero condensed cavity columns of the link pass, summed over the links (the pass skips
        the zero ones; 0 without cavities).
    points, spans : int
        Cable routing points and spans (0 without cables).
    values : int
        Values of the exact evaluation's tangent blocks: 144 per link, then the cable blocks
        (only these are scattered by the tick).
    jacobian_entries : int
        Nonzero entries of ``J_aᵀ``.
    effector_frames : tuple of int
        Frame (1..n) of every effector: ``J_eᵀ`` is zero above its rows, where its forward sweep
        and its products start.
    starts : tuple of int
        First nonzero row of each column of ``[r, J_aᵀ]`` (its forward sweep starts at that
        row's block).

    """

    n: int
    m: int
    k: int
    block_width: int
    cavities: int
    points: int
    spans: int
    values: int
    jacobian_entries: int
    effector_frames: tuple
    starts: tuple


def tick_shapes(solver):
    """
    Return the shapes of a solver's tick.

    Parameters
    ----------
    solver : cbha_inverse.core.inverse.solver.InverseSolver
        After at least one tick (``J_aᵀ`` and the factor's reach are read from its last
        linearisation).

    Returns
    -------
    TickShapes

    """
    system = solver._system
    record = system.record
    return TickShapes(system.n, system.m, len(solver.effector_names), system.block_width,
                      int((record.cavity_columns >= 0).sum()), record.cable_frames.size,
                      record.span_start.size, record.values.size,
                      int((record.rhs[:, 1:] != 0.0).sum()),
                      tuple(int(f) for f in solver.effectors.frames),
                      tuple(int(row) for row in solver._data.column_starts))


def tick_flops(shapes):
    """
    Return the flops of one linearising tick per phase (module docstring).

    Parameters
    ----------
    shapes : TickShapes
        The tick's sizes.

    Returns
    -------
    dict of str -> int
        ``links``, ``cables``, ``assembly``, ``factor``, ``solve``, ``projection``, ``qp``,
        ``update`` and their ``total``.

    """
    n, m, k = shapes.n, shapes.m, shapes.k
    size, rows, columns = 6 * n, 3 * shapes.k, m + 1
    links = (n * (_LINK_BASE + _LINK_PER_COLUMN)
             + (_LINK_PER_CAVITY + _LINK_PER_COLUMN) * shapes.cavities)
    # block Cholesky, per block column: the diagonal block's Cholesky, the blocks below times
    # its inverse, the trailing blocks' updates (lower triangle on the diagonal); the solve: the
    # forward sweeps of [r, J_aᵀ] and of J_eᵀ (3 columns per effector), each column from the
    # block of its first nonzero row (zero above it)
    width = shapes.block_width
    diagonal = sum(2 * j + 2 + (5 - j) * (2 * j + 1) for j in range(6))
    factor, solve, back = 0, 0, 0
    effector_starts = [6 * (frame - 1) for frame in shapes.effector_frames for _ in range(3)]
    for c in range(n):
        below = min(width, n - 1 - c)
        factor += (diagonal + below * 216 + below * (below - 1) // 2 * 432 + below * 252)
        row_sweep = 36 + 72 * below
        solve += row_sweep * sum(1 for start in list(shapes.starts) + effector_starts
                                 if 6 * c + 6 > start)
        back += row_sweep
    # the products of the half-solves: L⁻¹ J_eᵀ with L⁻¹ [r, J_aᵀ] from each effector's frame
    # on, the offset, the lower triangle of W_aa = (L⁻¹ J_aᵀ)ᵀ L⁻¹ J_aᵀ, |r|
    effector_rows = sum(size - 6 * (frame - 1) for frame in shapes.effector_frames)
    projection = (3 * effector_rows * columns * 2 + rows * m * 2 + size * m * (m + 1) + size * 2
                  # the QP matrices: W σ, Wᵀ W (upper triangle), normalisation, Hessian
                  + rows * m * 2 + rows * m * (m + 1) + m * m * 6)
    # QP vectors, one active-set iteration (free-block Cholesky, its solves, the multiplier
    # checks), the outcome and the binding bounds
    qp = (m * (2 * rows + 6) + (m ** 3) // 3 + 4 * m * m + 2 * m * m
          + (2 * rows * m + 4 * m + 5 * k) + 2 * m * m)
    # the step L⁻¹ r + L⁻¹ J_aᵀ Δλ, its backward sweep (one column), the retraction, the
    # effector positions
    update = size * 2 * m + back + n * _RETRACT_PER_FRAME + 18 * k
    # the assembly: the links add the symmetric parts of their blocks into the block band, the
    # cable blocks are scattered with their weights; the block band is zeroed first
    link_adds = _LINK_BAND * (n - 1) + _FIRST_LINK_BAND if n else 0
    cable_values = shapes.values - 144 * n
    counts = {'links': links,
              'cables': _CABLE_PER_POINT * shapes.points + _CABLE_PER_SPAN * shapes.spans,
              'assembly': link_adds + 2 * cable_values + size, 'factor': factor, 'solve': solve,
              'projection': projection, 'qp': qp, 'update': update}
    counts['total'] = sum(counts.values())
    return counts


def measured_flop_rate(repeats=20, n_steps=100_000):
    """
    Return this machine's rate of independent multiply-add chains [flop/s], best of some runs.

    Parameters
    ----------
    repeats : int
        Runs (the fastest counts: a loaded machine only slows runs down).
    n_steps : int
        Steps per run (16 flops each; 1.6 Mflop, ~0.2 ms, per run by default).

    Returns
    -------
    float  [flop/s]

    """
    multiply_add_chains(1, 0.5)
    best = float('inf')
    for _ in range(repeats):
        started = time.perf_counter()
        multiply_add_chains(n_steps, 0.5)
        best = min(best, time.perf_counter() - started)
    return 16.0 * n_steps / best
