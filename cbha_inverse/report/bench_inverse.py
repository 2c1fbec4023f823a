"""
Benchmark of the inverse-simulation control tick per scene (``cbha_bench_inverse``).

For every scene the solver tracks a circle in the y-z plane around the scene's workspace centre
(the paper's 60 mm circle for the CBHA, a 10 mm circle for the tendon trunks) and the table shows
the tick time (median and 99th percentile over the measured ticks) and its median breakdown (lin =
the linearisation: internal wrenches, tangent, actuator columns and load stiffness, block Cholesky,
the multi-RHS solve, the projection to W_ea, W_aa, δ_free and the QP matrices and the equilibrium
gap; QP = the box QP with its checks, with the active set also the Newton step and the effector
positions; with the active set a tick is one compiled call, its whole time under lin when it
linearises, else under QP; update = the rest: the check of the linearisation, Newton steps beyond
the first, the check of a large step's new state, the result) beside the figures reported in
the paper (SOFA, 2.66 GHz Core i7, 2015), and the distance to the limit: the tick's flops counted
from its shapes (:func:`cbha_inverse.report.tick_flops.tick_flops`), their time at this machine's
measured rate of multiply-add chains (``bound``) and the median over it (``x bound``). ``lin`` is
the ``relinearize_every`` option: 1 linearises at every tick (as the paper does); 5 keeps a
linearisation for up to 5 ticks (the ticks in between only re-solve the QP of the linear model, so
their phases before the QP are ~0 and the median is theirs; the p99 is the linearisation tick).
``QP`` compares the exact active-set solver (the default) with proxsuite. The last columns give
this machine's goal (median / p99, ``ok`` when met), the paper's tick time and the ratio paper /
ours. A second table times the static forward solve
(:func:`cbha_inverse.core.statics.solve_static`, which the simulated plant runs every tick) per
Newton iteration, in ticks of the same run. ``--contact`` times instead the tick with 0 to 4
active obstacle rows (``docs/obstacles.md``) against the obstacle-free tick
(:func:`bench_contact`).
"""

import argparse
import json
import os
import sys
import time

from cbha_inverse.core.inverse.qp import QP_SOLVERS
from cbha_inverse.core.obstacles import obstacle_from_rpy
from cbha_inverse.errors import ConfigError, report_config_error
from cbha_inverse.report.tick_flops import measured_flop_rate, tick_flops, tick_shapes
from cbha_inverse.scene import load_scene
import numpy as np

PAPER = {
    'tendon_6f_8c': 'paper: 6 frames / 4-8 tendons: 5 ms (W 2 ms, QP < 1 ms)',
    'tendon_10f_16c': 'paper: 10 frames / 16 tendons: 13 ms (W 9 ms)',
    'cbha': 'paper: not reported (open-loop CBHA runs)',
}
# the paper's tick times [s] (SOFA, 2.66 GHz Core i7) and this project's goals [s] (median, p99)
PAPER_TICK = {'tendon_6f_8c': 5e-3, 'tendon_10f_16c': 13e-3}
GOALS = {'tendon_6f_8c': (100e-6, None), 'tendon_10f_16c': (150e-6, None),
         'cbha': (150e-6, 500e-6)}
RADIUS = {'cbha': 0.06}
PHASES = ('assembly', 'factor', 'projection', 'qp', 'update', 'total')

MEASURED_TICKS = 20000
"""
Ticks measured per row (~0.3 s of CBHA ticks).

A pause of the shared machine of tens of ms covers a small part of them and leaves the median
where it is; over 2000 ticks (~0.1 s with the loop) one moved the CBHA's median by 7 µs.
"""


def circle_targets(center, radius, n_ticks, period_ticks):
    """
    Return targets on a circle in the y-z plane around the last effector's centre.

    Parameters
    ----------
    center : (k, 3) ndarray  [m]
        Centre; effectors other than the last stay there.
    radius : float  [m]
        Circle radius.
    n_ticks : int
        Number of targets.
    period_ticks : int
        Ticks per revolution.

    Returns
    -------
    (n_ticks, k, 3) ndarray  [m]

    """
    phase = 2.0 * np.pi * np.arange(n_ticks) / period_ticks
    targets = np.repeat(np.asarray(center, dtype=float)[None], n_ticks, axis=0)
    targets[:, -1, 1] += radius * np.cos(phase)
    targets[:, -1, 2] += radius * np.sin(phase)
    return targets


def bench_scene(name, n_ticks=MEASURED_TICKS, warmup=100, qp_solver='proxsuite', newton_steps=1,
                relinearize_every=1):
    """
    Run the tick on one scene and collect timings and tracking errors.

    Parameters
    ----------
    name : str
        Scene name (``config/scenes/<name>.yaml``).
    n_ticks : int
        Measured ticks.
    warmup : int
        Ticks run first (converge onto the circle, warm the caches), not measured.
    qp_solver : str
        ``'proxsuite'``, ``'active_set'`` or ``'gauss_seidel'``.
    newton_steps : int
        Newton steps per tick.
    relinearize_every : int
        Ticks between linearisations (1 = every tick, as in the paper).

    Returns
    -------
    dict
        Scene sizes, median / p99 of the total, median of each phase [s], tracking error [m],
        status counts.

    """
    scene = load_scene(name)
    solver = scene.make_inverse_solver(qp_solver=qp_solver, newton_steps=newton_steps,
                                       relinearize_every=relinearize_every)
    radius = RADIUS.get(name, 0.01)
    center = scene.workspace_center
    targets = circle_targets(center, radius, n_ticks + warmup, 500)
    first = targets[0]
    for _ in range(warmup):
        solver.step(first)
    times = {p: np.empty(n_ticks) for p in PHASES}
    errors = np.empty(n_ticks)
    statuses = {}
    for i in range(n_ticks):
        out = solver.step(targets[warmup + i])
        for p in PHASES:
            times[p][i] = out.timings.get(p, np.nan)
        # error of the model state (not of the linear prediction of a kept linearisation);
        # evaluated outside the timed tick
        errors[i] = np.linalg.norm(solver.effector_positions()[-1] - targets[warmup + i][-1])
        statuses[out.status] = statuses.get(out.status, 0) + 1
    flops = tick_flops(tick_shapes(solver))
    return {
        'scene': name,
        # a tick between linearisations only solves the QP
        'flops': flops['total'] if relinearize_every == 1 else flops['qp'],
        'frames': scene.model.n_links,
        'actuators': len(scene.actuator_names),
        'effectors': len(scene.effector_names),
        'qp_solver': qp_solver,
        'relinearize_every': relinearize_every,
        'median': {p: float(np.median(times[p])) for p in PHASES},
        'p99': float(np.percentile(times['total'], 99)),
        'mean': float(np.mean(times['total'])),
        'tracking_error_median': float(np.median(errors)),
        'tracking_error_max': float(errors.max()),
        'radius': radius,
        'status': statuses,
    }


CONTACT_BALL = 0.005
"""Radius of each obstacle ball of :func:`bench_contact` [m]."""
CONTACT_FRAMES = (16, 12, 8, 4)
"""The collision spheres :func:`bench_contact` puts a ball under, one more per row."""


def bench_contact(name='cbha_table', n_ticks=2000, warmup=50, max_rows=4):
    """
    Time the tick with 0 to ``max_rows`` active obstacle rows and without obstacles.

    The arm holds the equilibrium of 30 % of each actuator's range (its effector there is the
    target); a 5 mm ball sits 2.5 mm below each of the first ``rows`` spheres of
    :data:`CONTACT_FRAMES` (``obstacle_activation`` 1 mm: one row per ball, its neighbours'
    spheres stay out of reach); with no row, one ball a metre away. Every tick linearises
    (``step`` without ``prepare``).

    Parameters
    ----------
    name : str
        A scene with collision spheres.
    n_ticks, warmup : int
        Measured ticks per case, and ticks run first.
    max_rows : int
        Largest number of rows (at most ``len(CONTACT_FRAMES)``).

    Returns
    -------
    list of dict
        Per case: ``case`` (``'no obstacles'`` or the number of balls), ``rows`` (the median
        number of rows of its ticks), ``median`` and ``p99`` of the tick [s].

    """
    scene = load_scene(name)
    actuation = 0.3 * (scene.upper_bounds - scene.lower_bounds) + scene.lower_bounds
    equilibrium = scene.forward(actuation, strict=True, check_warnings=False)
    target = np.array(equilibrium.effector_positions)
    below = np.array([0.0, 0.0, -1.0])
    margin = scene.make_inverse_solver().options.obstacle_margin
    balls = []
    for frame in CONTACT_FRAMES[:max_rows]:
        sphere = list(scene.collision.frames).index(frame)
        centre = equilibrium.positions[frame] + below * (
            scene.collision.radii[sphere] + margin + 0.5 * 1e-3 + CONTACT_BALL)
        balls.append(obstacle_from_rpy(f'ball_{frame}', 'sphere', centre, (0.0, 0.0, 0.0),
                                       radius=CONTACT_BALL))
    # no row: one ball a metre away (the distance query and the QP of the rows' path, no row)
    far = obstacle_from_rpy('far', 'sphere', target[0] + [0.0, 0.0, -1.0], (0.0, 0.0, 0.0),
                            radius=CONTACT_BALL)
    rows = []
    for count in [None] + list(range(max_rows + 1)):
        solver = scene.make_inverse_solver(obstacle_activation=1e-3)
        solver.set_obstacles(() if count is None else balls[:count] or [far])
        solver.reset(equilibrium.state, actuation)
        for _ in range(warmup):
            solver.step(target)
        times, active = np.empty(n_ticks), np.empty(n_ticks)
        for i in range(n_ticks):
            out = solver.step(target)
            times[i], active[i] = out.timings['total'], out.obstacle_rows
        rows.append({'case': 'no obstacles' if count is None else count,
                     'rows': float(np.median(active)), 'median': float(np.median(times)),
                     'p99': float(np.percentile(times, 99))})
    return rows


def format_contact(rows):
    """Return the table of :func:`bench_contact` (ticks in µs, ratio to the obstacle-free)."""
    free = rows[0]['median']
    lines = [f"{'obstacles':>12s} {'rows':>5s} {'median':>8s} {'p99':>8s} {'x free':>7s}"]
    for r in rows:
        lines.append(f"{str(r['case']):>12s} {r['rows']:5.0f} {1e6 * r['median']:7.1f}u "
                     f"{1e6 * r['p99']:7.1f}u {r['median'] / free:7.2f}")
    return '\n'.join(lines)


def bench_forward(name, repeats=50, n_cases=6, seed=3):
    """
    Time one Newton iteration of the static forward solve (the solver the plant runs).

    Each case is an actuation drawn uniformly within 10-70 % of the bounds, solved cold from the
    rest shape; from that equilibrium, warm-started solves of the actuation moved by 0, 0.5, 2
    and 5 % of the range take from none to a few Newton iterations, as the simulated plant's
    solves do every tick (without the result's warnings, ``check_warnings=False``). The best of
    ``repeats`` runs of each solve against its iterations gives, by least squares, the time of
    one iteration (the slope: the compiled point, direction and line-search trials and the
    Python between them) and the fixed cost of a solve (the intercept: setup, first residual,
    result).

    Parameters
    ----------
    name : str
        Scene name.
    repeats : int
        Runs of every solve (the minimum time is kept).
    n_cases : int
        Actuations.
    seed : int
        Seed of the actuations.

    Returns
    -------
    dict
        ``per_iteration`` and ``per_solve`` [s], the cold solves' mean ``cold_iterations`` and
        the warm solves' ``warm_iterations`` (list).

    """
    scene = load_scene(name)
    low, high = scene.lower_bounds, scene.upper_bounds
    rng = np.random.default_rng(seed)
    iterations, seconds, cold_iterations = [], [], []
    for _ in range(n_cases):
        actuation = low + (high - low) * rng.uniform(0.1, 0.7, low.size)
        cold = scene.forward(actuation, strict=True, check_warnings=False)
        cold_iterations.append(cold.iterations)
        for fraction in (0.0, 0.005, 0.02, 0.05):
            nearby = np.minimum(actuation + fraction * (high - low), high)
            best = np.inf
            for _ in range(repeats):
                started = time.perf_counter()
                result = scene.forward(nearby, initial_state=cold.state, check_warnings=False)
                best = min(best, time.perf_counter() - started)
            if not result.converged:
                raise RuntimeError(f'{name}: forward solve did not converge ({result.message})')
            iterations.append(result.iterations)
            seconds.append(best)
    if len(set(iterations)) < 2:
        raise RuntimeError(f'{name}: the warm solves all took {iterations[0]} iterations')
    per_iteration, per_solve = np.polyfit(iterations, seconds, 1)
    return {'scene': name, 'per_iteration': float(per_iteration), 'per_solve': float(per_solve),
            'cold_iterations': float(np.mean(cold_iterations)),
            'warm_iterations': [int(i) for i in iterations]}


def format_forward(forward_rows, tick_medians):
    """
    Format the forward-solve costs beside the tick median of the same run.

    Parameters
    ----------
    forward_rows : list of dict
        From :func:`bench_forward`.
    tick_medians : dict of str -> float
        Tick median [s] per scene (active-set QP, linearising every tick).

    Returns
    -------
    str

    """
    lines = ['', 'Forward (static) solve as the plant runs it: one Newton iteration vs one '
             'control tick (same run; goal <= 2 ticks)',
             f"{'scene':16s} {'iter cold':>9s} {'iter warm':>9s} {'per iter':>9s} "
             f"{'per solve':>9s} {'tick':>8s} {'ticks/iter':>10s}"]
    for r in forward_rows:
        tick = tick_medians[r['scene']]
        warm = r['warm_iterations']
        lines.append(f"{r['scene']:16s} {r['cold_iterations']:9.1f} "
                     f"{f'{min(warm)}-{max(warm)}':>9s} {1e6 * r['per_iteration']:7.0f}us "
                     f"{1e6 * r['per_solve']:7.0f}us {1e6 * tick:6.0f}us "
                     f"{r['per_iteration'] / tick:10.2f}")
    lines.append('per iter / per solve: least-squares slope / intercept of the best time of '
                 'warm-started solves against their Newton iterations')
    return '\n'.join(lines)


def format_table(rows, flop_rate):
    """
    Format benchmark rows as a plain-text table.

    Per row: tick median and p99, the median of each phase, the flops, their bound and the
    median over it, the goal of this machine (median / p99, ``ok`` when met), the paper's tick
    time and the ratio paper / ours (median).

    Parameters
    ----------
    rows : list of dict
        From :func:`bench_scene`.
    flop_rate : float  [flop/s]
        From :func:`cbha_inverse.report.tick_flops.measured_flop_rate`, measured in the run.

    Returns
    -------
    str

    """
    head = (f"{'scene':16s} {'n':>3s} {'m':>3s} {'k':>2s} {'QP':>10s} {'lin':>3s} {'median':>8s} "
            f"{'p99':>8s} | {'lin':>7s} {'QP':>7s} {'update':>7s} | {'kflop':>6s} {'bound':>7s}"
            f" {'x bound':>7s} | {'err med':>8s} | {'goal med/p99':>16s} | {'paper':>6s}"
            f" {'paper/us':>8s}")
    lines = [head, '-' * len(head)]
    for r in rows:
        med = r['median']
        us = {p: 1e6 * med[p] for p in PHASES}
        goal_med, goal_p99 = GOALS.get(r['scene'], (None, None))
        goal = '-'
        if goal_med is not None:
            met = med['total'] <= goal_med and (goal_p99 is None or r['p99'] <= goal_p99)
            goal = (f"{1e6 * goal_med:.0f}/{'-' if goal_p99 is None else f'{1e6 * goal_p99:.0f}'}"
                    f"us {'ok' if met else 'NO'}")
        paper = PAPER_TICK.get(r['scene'])
        bound = r['flops'] / flop_rate
        ratio = (f"{paper / med['total']:7.1f}x" if paper else '       -')
        paper_text = f'{1e3 * paper:4.0f}ms' if paper else '     -'
        lines.append(
            f"{r['scene']:16s} {r['frames']:3d} {r['actuators']:3d} {r['effectors']:2d} "
            f"{r['qp_solver']:>10s} {r['relinearize_every']:3d} "
            f"{us['total']:6.1f}us {1e6 * r['p99']:6.0f}us | "
            f"{us['assembly']:5.1f}us {us['qp']:5.1f}us {us['update']:5.1f}us | "
            f"{r['flops'] / 1e3:6.1f} {1e6 * bound:5.1f}us {med['total'] / bound:6.1f}x | "
            f"{1e3 * r['tracking_error_median']:6.3f}mm | {goal:>16s} | {paper_text} {ratio}")
    lines.append('')
    lines.append('lin / QP / update: a tick of the active set runs as one compiled call, its '
                 'whole time under lin when it linearises, else under QP; update: the rest')
    lines += [f'{name}: {text}' for name, text in PAPER.items()]
    return '\n'.join(lines)


def main(argv=None):
    """
    Print the per-scene tick-time table (``cbha_bench_inverse``).

    Parameters
    ----------
    argv : list of str, optional
        Command-line arguments (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        Exit status.

    """
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--scenes', nargs='+', default=['tendon_6f_8c', 'tendon_10f_16c',
                                                        'cbha'])
    parser.add_argument('--ticks', type=int, default=MEASURED_TICKS,
                        help=f'measured ticks per row (default {MEASURED_TICKS})')
    parser.add_argument('--warmup', type=int, default=100)
    parser.add_argument('--qp-solvers', nargs='+', default=['proxsuite', 'active_set'],
                        choices=QP_SOLVERS,
                        help='QP solvers to compare (default: proxsuite and the exact active set)')
    parser.add_argument('--gauss-seidel', action='store_true',
                        help='also run the projected Gauss-Seidel QP for comparison')
    parser.add_argument('--relinearize-every', type=int, nargs='+', default=[1, 5],
                        help='ticks between linearisations to compare (1 = every tick)')
    parser.add_argument('--json', help='write the rows to this JSON file')
    parser.add_argument('--contact', action='store_true',
                        help='time the tick with 0-4 active obstacle rows on cbha_table '
                             'instead (the ticks per case: --ticks)')
    args = parser.parse_args(argv)
    if args.contact:
        print(format_contact(bench_contact(n_ticks=args.ticks, warmup=args.warmup)))
        return 0
    try:
        for name in args.scenes:
            load_scene(name)
    except (ConfigError, FileNotFoundError) as exc:
        return report_config_error('cbha_bench_inverse', exc)
    rows = []
    started = time.perf_counter()
    flop_rate = measured_flop_rate()
    for name in args.scenes:
        solvers = list(args.qp_solvers) + (['gauss_seidel'] if args.gauss_seidel
                                           and 'gauss_seidel' not in args.qp_solvers else [])
        for qp_solver in solvers:
            for every in args.relinearize_every:
                rows.append(bench_scene(name, args.ticks, args.warmup, qp_solver,
                                        relinearize_every=every))
    # the rate again after the ticks: the faster of the two (the machine is shared)
    flop_rate = max(flop_rate, measured_flop_rate())
    print(format_table(rows, flop_rate))
    print(f'flop rate of independent multiply-add chains on this machine: '
          f'{flop_rate / 1e9:.1f} Gflop/s (bound = kflop / rate)')
    tick_medians = {}
    for name in args.scenes:
        same = [r for r in rows if r['scene'] == name and r['qp_solver'] == 'active_set'
                and r['relinearize_every'] == 1]
        row = same[0] if same else bench_scene(name, args.ticks, args.warmup, 'active_set')
        tick_medians[name] = row['median']['total']
    forward = [bench_forward(name) for name in args.scenes]
    print(format_forward(forward, tick_medians))
    print(f'goals on the shared 2-core machine: 6f/8c <= 100 us, 10f/16c <= 150 us, '
          f'CBHA <= 150 us median, p99 <= 500 us; one BLAS thread '
          f"(OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')}); "
          f'({time.perf_counter() - started:.1f} s)')
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as f:
            json.dump({'ticks': rows, 'forward': forward}, f, indent=2)
    return 0


if __name__ == '__main__':
    sys.exit(main())
