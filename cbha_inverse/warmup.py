"""
Compile the numba kernels the shipped scenes use into numba's on-disk cache (run at install).

The kernels (the modules of :mod:`cbha_inverse.core._kernels`) are ``numba.njit(cache=True)``:
the first process that calls them compiles them and writes the machine code to ``__pycache__``
next to the sources (or to ``NUMBA_CACHE_DIR``); later processes load it (a fraction of a second
for a first tick). This module runs, on every shipped scene, what a node or a command runs: the
control ticks of every QP solver and option branch, a static solve (the forward model, the
plant), the obstacles' signed distance and the shape estimator's updates, so that each kernel is
compiled once, at install, and never inside a timed test, the demo or a control loop. The
benchmarks' own kernels (the compiled BTD backend, the flop-rate loop) are left to the
benchmarks, which time repeated calls.

Usage: ``python -m cbha_inverse.warmup [--scenes NAME ...]``. Pure numerics, no rclpy.
"""

import argparse
import sys
import time

from cbha_inverse.core.inverse.qp import QP_SOLVERS
from cbha_inverse.estimate.shape import ShapeEstimator
from cbha_inverse.paths import config_path
from cbha_inverse.scene import load_scene
import numpy as np

SCENES = ('tendon_6f_8c', 'tendon_10f_16c', 'cbha')


def option_sets(n_actuators, span):
    """
    Return the solver options the warm-up runs on a scene.

    Every QP solver with the default options, then the other branches of the tick: a rate limit
    (the QP bounds of :func:`cbha_inverse.core.inverse.qp.qp_problem`), linear ticks and the
    pending linear step (``relinearize_every > 1``) and the full Newton steps at fixed actuation
    (``newton_steps > 1``).

    Parameters
    ----------
    n_actuators : int
        Number of actuators ``m``.
    span : (m,) ndarray  [N or Pa]
        ``upper - lower`` of each actuator.

    Returns
    -------
    list of dict
        Keyword arguments of :meth:`cbha_inverse.scene.Scene.make_inverse_solver`.

    """
    options = [{'qp_solver': qp_solver} for qp_solver in QP_SOLVERS]
    options.append({'rate_limit': tuple(0.05 * np.asarray(span, dtype=float)[:n_actuators]),
                    'relinearize_every': 5, 'newton_steps': 2})
    return options


def warm_targets(center, radius, n_ticks=6):
    """
    Return a few targets on an arc around the last effector's centre, then a far one.

    Effectors other than the last stay at their centre (as in
    :func:`cbha_inverse.report.bench_inverse.circle_targets`). The far target saturates the
    actuators, so the bound-handling kernels compile too.

    Parameters
    ----------
    center : (k, 3) ndarray  [m]
        Centre of the effectors (``scene.workspace_center``).
    radius : float  [m]
        Arc radius.
    n_ticks : int
        Number of targets on the arc.

    Returns
    -------
    (n_ticks + 1, k, 3) ndarray  [m]

    """
    phase = np.linspace(0.0, 0.5 * np.pi, n_ticks)
    targets = np.repeat(np.asarray(center, dtype=float)[None], n_ticks + 1, axis=0)
    targets[:n_ticks, -1, 1] += radius * np.cos(phase)
    targets[:n_ticks, -1, 2] += radius * np.sin(phase)
    targets[n_ticks, -1] += [0.0, 1.0, -1.0]
    return targets


def warm_control(name):
    """
    Run the control ticks of one scene with every option set, then its shape estimator.

    Parameters
    ----------
    name : str
        Scene name (``config/scenes/<name>.yaml``).

    """
    scene = load_scene(name)
    radius = 0.06 if name == 'cbha' else 0.01
    targets = warm_targets(scene.workspace_center, radius)
    for options in option_sets(len(scene.actuator_names),
                               scene.upper_bounds - scene.lower_bounds):
        solver = scene.make_inverse_solver(**options)
        solver.warm_up()
        for target in targets:
            solver.step(target)
            solver.prepare()
    if scene.sensors is not None:
        ShapeEstimator.from_scene(scene).warm_up()


def warm_statics(name):
    """
    Run one static solve of one scene at mid actuation (the forward model, the plant).

    Parameters
    ----------
    name : str
        Scene name.

    """
    scene = load_scene(name)
    scene.forward(0.5 * (scene.lower_bounds + scene.upper_bounds))


def warm_obstacles():
    """Run the signed-distance queries of one obstacle of each shape (the plant's contact)."""
    from cbha_inverse.core.obstacles import (Obstacle, pack_obstacles,
                                             pairwise_signed_distance)
    points = np.array([[0.0, 0.0, 0.0], [0.1, -0.05, 0.2]])
    obstacles = [Obstacle(shape, shape, np.zeros(3), np.eye(3), **sizes) for shape, sizes in (
        ('plane', {}), ('sphere', {'radius': 0.03}), ('box', {'size': (0.04, 0.06, 0.1)}),
        ('capsule', {'radius': 0.02, 'length': 0.08}),
        ('cylinder', {'radius': 0.02, 'length': 0.08}))]
    for obstacle in obstacles:
        obstacle.signed_distance(points)
    pairwise_signed_distance(pack_obstacles(obstacles), points)


def main(argv=None):
    """
    Compile (or load) every kernel the shipped scenes use; print the time.

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
    parser.add_argument('--scenes', nargs='+', default=list(SCENES), choices=SCENES,
                        help='scenes to run (default: all)')
    args = parser.parse_args(argv)
    started = time.perf_counter()
    names = []
    for name in args.scenes:
        if name == 'cbha' and not config_path('segments', 'cbha_segment.yaml').is_file():
            print('warm-up: skipping cbha (the condensed CBHA segment is not generated yet)')
            continue
        warm_control(name)
        warm_statics(name)
        names.append(name)
    warm_obstacles()
    print(f'warm-up: numba kernels compiled or loaded from the cache in '
          f'{time.perf_counter() - started:.1f} s ({", ".join(names) or "no scene"})',
          flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
