"""
``cbha_scene check SCENE``: what a scene builds, before any node runs it.

Prints the frames, the actuators and their bounds, the effectors at rest (under the scene's
gravity), the reach along each actuator (the tip displacement with that actuator alone at its
upper bound), the suggested workspace centre and the inverse solver's tick time (median and p99
of a run toward the centre). Exit status 0; 1 if a forward solve does not converge; 2 on a bad
scene file (one line naming the file and the key).
"""

import argparse
import sys
import time

from cbha_inverse.core.actuation.cables import CableGroup
from cbha_inverse.errors import ConfigError, report_config_error
import numpy as np

PROGRAM = 'cbha_scene'


def _parser():
    parser = argparse.ArgumentParser(prog=PROGRAM, description=__doc__.strip().splitlines()[0])
    commands = parser.add_subparsers(dest='command', required=True)
    check = commands.add_parser('check', help='load a scene and report what it builds')
    check.add_argument('scene', help='scene YAML: a path, or a name in config/scenes')
    check.add_argument('--ticks', type=int, default=200, help='solver ticks timed (default 200)')
    return parser


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


def check(scene_path, ticks, out):
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

    Returns
    -------
    int
        0 (1 if a forward solve does not converge).

    """
    from cbha_inverse.scene import load_scene, resolve_scene_path
    path = resolve_scene_path(scene_path)
    started = time.perf_counter()
    scene = load_scene(path)
    loaded = time.perf_counter() - started
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

    """
    args = _parser().parse_args(argv)
    try:
        return check(args.scene, args.ticks, sys.stdout)
    except (ConfigError, FileNotFoundError) as exc:
        return report_config_error(PROGRAM, exc)


if __name__ == '__main__':
    sys.exit(main())
