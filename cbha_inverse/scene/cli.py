"""
``cbha_scene check SCENE``: what a scene builds, before any node runs it.

Prints the frames, the actuators and their bounds, the effectors at rest (under the scene's
gravity), the reach along each actuator (the tip displacement with that actuator alone at its
upper bound), the suggested workspace centre, the inverse solver's tick time (median and p99
of a run toward the centre) and the reachable set (``--reach-samples`` forward solves,
:func:`cbha_inverse.scene.reach.sample_reachable_set`: its box, its centre and the largest
circle around that centre in each principal plane). Exit status 0; 1 if a forward solve does not
converge; 2 on a bad scene file (one line naming the file and the key) or option.
"""

import argparse
import sys
import time

from cbha_inverse.core.actuation.cables import CableGroup
from cbha_inverse.errors import ConfigError, report_config_error
import numpy as np

PROGRAM = 'cbha_scene'
DEFAULT_REACH_SAMPLES = 300
"""Default ``--reach-samples`` (:data:`cbha_inverse.scene.reach.DEFAULT_SAMPLES`)."""


def _parser():
    parser = argparse.ArgumentParser(prog=PROGRAM, description=__doc__.strip().splitlines()[0])
    commands = parser.add_subparsers(dest='command', required=True)
    check = commands.add_parser('check', help='load a scene and report what it builds')
    check.add_argument('scene', help='scene YAML: a path, or a name in config/scenes')
    check.add_argument('--ticks', type=int, default=200, help='solver ticks timed (default 200)')
    check.add_argument('--reach-samples', type=int, default=DEFAULT_REACH_SAMPLES, metavar='N',
                       help='actuations sampled for the reachable set (default '
                            f'{DEFAULT_REACH_SAMPLES}; 0 skips it)')
    return parser


class _BadOption(ValueError):
    """An option value the scene rules out (reported like argparse's own errors)."""


def _millimetres(point):
    return '[' + ', '.join(f'{1e3 * v:.1f}' for v in point) + '] mm'


def actuator_units(scene):
    """Return the unit of each actuator in scene order (``N`` for cables, ``Pa`` otherwise)."""
    units = {}
    for group in scene.actuators.groups:
        for name in group.names:
            units[name] = 'N' if isinstance(group, CableGroup) else 'Pa'
    return [units[name] for name in scene.actuator_names]


def reach(scene):
    """
    Return the effector displacement of each actuator alone at its upper bound.

    Parameters
    ----------
    scene : cbha_inverse.scene.Scene
        The scene.

    Returns
    -------
    (m, k, 3) ndarray  [m]
        Displacement from the rest effector positions, per actuator.

    Raises
    ------
    RuntimeError
        If a forward solve does not converge.

    """
    rest = scene.rest_effector_positions
    moved = []
    for index in range(len(scene.actuator_names)):
        actuation = np.array(scene.lower_bounds, dtype=float)
        actuation[index] = scene.upper_bounds[index]
        moved.append(scene.forward(actuation, strict=True).effector_positions - rest)
    return np.array(moved)


def tick_times(scene, targets, ticks):
    """Return the per-tick times [s] of ``ticks`` solver steps toward ``targets`` (k, 3)."""
    solver = scene.make_inverse_solver()
    solver.warm_up()
    times = []
    for _ in range(ticks):
        start = time.perf_counter()
        solver.step(targets)
        times.append(time.perf_counter() - start)
    return np.array(times)


def print_reach(scene, samples, out):
    """
    Sample the reachable set of the last effector and print it (after ``check``'s lines).

    Parameters
    ----------
    scene : cbha_inverse.scene.Scene
        The scene.
    samples : int
        Actuations sampled (:func:`cbha_inverse.scene.reach.sample_reachable_set`).
    out : file-like
        Where the lines go.

    Returns
    -------
    cbha_inverse.scene.reach.ReachableSet
        The sampled set.

    Raises
    ------
    RuntimeError
        If fewer than 3 forward solves converge.

    """
    from cbha_inverse.scene.reach import sample_reachable_set
    started = time.perf_counter()
    reach = sample_reachable_set(scene, samples)
    took = time.perf_counter() - started
    print(f'reachable set of {reach.effector}: {samples} samples, {reach.failed} not converged, '
          f'{took:.2f} s', file=out)
    print(f'  box: {_millimetres(reach.box_min)} to {_millimetres(reach.box_max)}', file=out)
    print(f'  reachable centre: {_millimetres(reach.center)}', file=out)
    print(f'  largest circle around it: {_circles(reach.radii)} (in the hull of the samples, '
          'an estimate: plan 20 % smaller)', file=out)
    around = reach.radii_around(scene.workspace_center[-1])
    print(f'  around the workspace centre: {_circles(around)}', file=out)
    return reach


def _circles(radii):
    return ', '.join(f'{plane} {1e3 * radius:.1f} mm' for plane, radius in radii.items())


def check(scene_path, ticks, out, reach_samples=DEFAULT_REACH_SAMPLES):
    """
    Load a scene and print what it builds.

    Parameters
    ----------
    scene_path : str
        Scene path or name.
    ticks : int
        Solver ticks to time.
    out : file-like
        Where the report goes.
    reach_samples : int
        Actuations sampled for the reachable set (0 skips it).

    Returns
    -------
    int
        0 (1 if a forward solve does not converge).

    Raises
    ------
    ValueError
        If ``reach_samples`` is neither 0 nor enough for the scene's actuators.

    """
    from cbha_inverse.scene import load_scene, resolve_scene_path
    from cbha_inverse.scene.reach import fewest_samples
    path = resolve_scene_path(scene_path)
    started = time.perf_counter()
    scene = load_scene(path)
    loaded = time.perf_counter() - started
    fewest = fewest_samples(len(scene.actuator_names))
    if reach_samples != 0 and reach_samples < fewest:
        raise _BadOption(f'--reach-samples must be 0 (skip) or >= {fewest} for '
                         f'{len(scene.actuator_names)} actuators, got {reach_samples}')
    model = scene.model
    print(f'scene {scene.name} ({path}), loaded in {loaded:.2f} s', file=out)
    if scene.description:
        print(f'  {scene.description.strip()}', file=out)
    print(f'frames: {model.n_frames} (base {scene.base_frame} + {model.n_links} links), mass '
          f'{float(np.sum(model.masses)):.4g} kg, gravity '
          f'{"none" if scene.gravity is None else scene.gravity.tolist()} m/s^2', file=out)
    units = actuator_units(scene)
    print(f'actuators: {len(scene.actuator_names)}', file=out)
    for name, low, high, unit in zip(scene.actuator_names, scene.lower_bounds,
                                     scene.upper_bounds, units):
        print(f'  {name}: [{low:g}, {high:g}] {unit}', file=out)
    try:
        rest = scene.rest_effector_positions
        displacements = reach(scene)
    except RuntimeError as exc:
        print(f'error: {exc}', file=out)
        return 1
    for name, point in zip(scene.effector_names, rest):
        print(f'effector {name} at rest: {_millimetres(point)}', file=out)
    print('reach (effector displacement, each actuator alone at its upper bound):', file=out)
    for name, moved in zip(scene.actuator_names, displacements):
        print(f'  {name}: ' + '; '.join(
            f'{effector} {_millimetres(d)} |{1e3 * np.linalg.norm(d):.1f} mm|'
            for effector, d in zip(scene.effector_names, moved)), file=out)
    center = scene.workspace_center
    print(f'workspace centre: {_millimetres(center[-1])}', file=out)
    times = tick_times(scene, center, ticks)
    print(f'tick: median {1e6 * np.median(times):.0f} us, p99 {1e6 * np.quantile(times, 0.99):.0f}'
          f' us over {ticks} ticks toward the workspace centre', file=out)
    if reach_samples:
        try:
            print_reach(scene, reach_samples, out)
        except RuntimeError as exc:
            print(f'error: {exc}', file=out)
            return 1
    return 0


def main(argv=None):
    """
    Run the ``cbha_scene`` command.

    Parameters
    ----------
    argv : list of str, optional
        Arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        0, 1 (a forward solve failed) or 2 (bad scene file).

    Raises
    ------
    SystemExit
        With status 2 on a bad option (argparse's usage and one line).

    """
    parser = _parser()
    args = parser.parse_args(argv)
    try:
        return check(args.scene, args.ticks, sys.stdout, args.reach_samples)
    except (ConfigError, FileNotFoundError) as exc:
        return report_config_error(PROGRAM, exc)
    except _BadOption as exc:
        parser.error(str(exc))


if __name__ == '__main__':
    sys.exit(main())
