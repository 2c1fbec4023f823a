"""
``cbha_report rao2021``: the package's model on the benchmark robot of Rao et al. 2021.

Rao, Peyron, Lilge and Burgner-Kahrs, *How to Model Tendon-Driven Continuum Robots and Benchmark
Modelling Performance*, Frontiers in Robotics and AI 7:630245, 2021, compare models of a
two-segment tendon-driven continuum robot against a reference: a Cosserat rod between every two
disks, the tendons in straight spans between the disks (a variable-curvature model with a
partially constrained tendon path). The robot is the scene ``rao2021_tdcr`` (the numbers of the
authors' public code); the reference is solved by
:mod:`cbha_inverse.report.subsegment_cosserat`, independently of the package's model.

For each case (tendon tensions, a dead tip force) the report solves the scene's static
equilibrium (:func:`cbha_inverse.core.statics.solve_static`) and the reference, and prints the
two tip positions and their distance in mm and in % of the robot's length, also against the
reference with the tendons' force on a disk they pass through taken as that of a frictionless
point contact (the package's cable model) instead of the paper's in-plane force. ``--beams N``
solves the scene with N Timoshenko beams between two disks instead of its own; ``--refine``
adds our tip error at twice and four times as many and the Richardson extrapolation of the last
two (the model's limit as the beams get shorter).

The robot, the cases and the results: docs/benchmark-rao2021.md.
"""

import argparse
from dataclasses import dataclass
import sys
import time

import numpy as np

SCENE = 'rao2021_tdcr'
"""The benchmark robot's scene (config/scenes)."""

SCENE_FROM_PAPER = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
"""Rotation from the paper's axes (backbone +z) to the scene's: their x, y, z = our y, z, x."""


@dataclass(frozen=True)
class Case:
    """
    One load case of the benchmark.

    Attributes
    ----------
    name : str
    tensions : tuple of float  [N]
        One per tendon, in the scene's actuator order (s1_90, s1_330, s1_210, s2_90, s2_330,
        s2_210: segment 1 ends at disk 10, segment 2 at the tip).
    tip_force : tuple of 3 floats  [N]
        Dead force at the tip disk's centre, scene axes (+x along the backbone at rest).
    note : str
        What the case is, and where it comes from.

    """

    name: str
    tensions: tuple
    tip_force: tuple
    note: str


CASES = (
    Case('planar_1', (4.0, 0, 0, 0, 0, 0), (0.0, 0.0, 0.0),
         'segment 1 bent in the x-z plane, segment 2 straight'),
    Case('planar_c', (2.0, 0, 0, 2.0, 0, 0), (0.0, 0.0, 0.0),
         'both segments bent the same way (C shape)'),
    Case('planar_s', (4.0, 0, 0, 0, 2.0, 2.0), (0.0, 0.0, 0.0),
         'segment 2 bent against segment 1 (S shape)'),
    Case('spatial_cpp', (4.0, 0, 0, 0, 2.0, 0), (0.0, 0.0, 0.0),
         'the tensions of the public code (c++/main.cpp)'),
    Case('spatial_matlab', (2.0, 0, 0, 0, 1.0, 0), (0.0, 0.0, 0.0),
         'the tensions of the public code (matlab/main.m)'),
    Case('planar_c_load', (2.0, 0, 0, 2.0, 0, 0), (0.0, 0.0, -0.1),
         'planar_c with 0.1 N at the tip against the bending'),
    Case('spatial_load', (4.0, 0, 0, 0, 2.0, 0), (0.0, 0.1, 0.0),
         'spatial_cpp with 0.1 N at the tip along +y'),
)
"""The benchmark's cases."""


def reference_robot(spec):
    """
    Return the paper's reference model of a ``beam_vertebrae`` tendon scene.

    Parameters
    ----------
    spec : dict
        The scene file (``beam_vertebrae`` chain; straight cables from the base, no helix; no
        calibration).

    Returns
    -------
    cbha_inverse.report.subsegment_cosserat.TendonRobot
        Disks at the vertebrae, the holes in the paper's axes (a scene hole at angle a lies at
        ``[r cos a, r sin a, 0]``), in the scene's cable order.

    Raises
    ------
    ValueError
        If the scene is of another kind.

    """
    from cbha_inverse.report.subsegment_cosserat import TendonRobot
    chain = spec['chain']
    if chain.get('type') != 'beam_vertebrae' or spec.get('cavities'):
        raise ValueError('the reference needs a beam_vertebrae chain with cables only')
    if spec.get('calibration'):
        raise ValueError('the reference models no calibration block')
    holes, ends = [], []
    for cable in spec['cables']:
        if 'points' in cable or cable.get('start_vertebra', 0) != 0 or 'helix' in cable:
            raise ValueError(f"cable {cable['name']}: the reference routes straight cables "
                             'from the base only')
        angle = np.deg2rad(cable['angle_deg'])
        holes.append([cable['radius'] * np.cos(angle), cable['radius'] * np.sin(angle), 0.0])
        ends.append(int(cable['end_vertebra']))
    backbone = chain['backbone']
    return TendonRobot((float(chain['interval_length']),) * int(chain['n_vertebrae']),
                       float(backbone['youngs_modulus']), float(backbone['poisson_ratio']),
                       float(backbone['outer_radius']), float(backbone.get('inner_radius', 0.0)),
                       tuple(map(tuple, holes)), tuple(ends))


def our_tip(scene, case):
    """
    Return the package's tip position [m] for a case (:func:`solve_static` of the scene).

    Parameters
    ----------
    scene : cbha_inverse.scene.scene.Scene
        The robot (a scene with its tendons and a tip effector last).
    case : Case
        Tensions in the scene's actuator order and the tip force.

    Returns
    -------
    (3,) ndarray  [m]
        Scene axes.

    Raises
    ------
    RuntimeError
        If the static solve does not converge.

    """
    from cbha_inverse.core.statics import solve_static
    result = solve_static(scene.model, tip_wrench=np.r_[case.tip_force, 0.0, 0.0, 0.0],
                          gravity=scene.gravity, actuators=scene.actuators,
                          actuation=np.asarray(case.tensions, dtype=float),
                          effectors=scene.effectors)
    if not result.converged:
        raise RuntimeError(f'{scene.name}, case {case.name}: {result.message}')
    return result.effector_positions[-1]


def reference_tip(robot, case, pass_through='disk_plane'):
    """
    Return the reference model's tip position [m] for a case, in scene axes.

    Parameters
    ----------
    robot : cbha_inverse.report.subsegment_cosserat.TendonRobot
        The reference model of the scene (:func:`reference_robot`).
    case : Case
        Tensions in the scene's actuator order and the tip force (scene axes).
    pass_through : {'disk_plane', 'eyelet'}
        The paper's tendon force on the disks it passes through, or a point contact's
        (:func:`cbha_inverse.report.subsegment_cosserat.solve_rod`).

    Returns
    -------
    (3,) ndarray  [m]

    """
    from cbha_inverse.report.subsegment_cosserat import solve_rod
    force = SCENE_FROM_PAPER.T @ np.asarray(case.tip_force, dtype=float)
    solution = solve_rod(robot, case.tensions, np.r_[force, 0.0, 0.0, 0.0],
                         pass_through=pass_through)
    return SCENE_FROM_PAPER @ solution.tip


def _scene_with_beams(spec, path, beams):
    """Return the scene of ``spec`` with ``beams`` beams per interval (written to ``path``)."""
    from cbha_inverse.scene import load_scene
    import yaml
    changed = dict(spec, chain=dict(spec['chain'], beams_per_interval=int(beams)))
    path.write_text(yaml.safe_dump(changed, sort_keys=False))
    return load_scene(path)


def benchmark(scene_name=SCENE, cases=CASES, refine=False, beams=None):
    """
    Solve every case with the package's model and the paper's reference.

    Parameters
    ----------
    scene_name : str
        A scene path or a name in ``config/scenes``.
    cases : sequence of Case
        The cases to solve.
    refine : bool
        Also solve the scene with 2 and 4 times its beams per interval.
    beams : int, optional
        Beams per interval instead of the scene's.

    Returns
    -------
    rows : list of dict
        Per case: ``case``, ``ours``, ``reference``, ``reference_eyelet`` (tips [m], scene
        axes), ``error`` and ``error_eyelet`` [m] (ours to each), ``length`` [m]; with
        ``refine``, ``refined`` ({factor: tip}) and ``extrapolated`` (Richardson, from factors
        2 and 4).
    beams : int
        The beams per interval solved.

    Raises
    ------
    ValueError
        If ``beams`` is below 1, or the scene is not a straight-cable beam scene.

    """
    import tempfile
    from pathlib import Path

    from cbha_inverse.config_files import read_yaml
    from cbha_inverse.scene import load_scene
    from cbha_inverse.scene.loader import resolve_scene_path
    path = resolve_scene_path(scene_name)
    spec = read_yaml(path)
    robot = reference_robot(spec)
    length = float(np.sum(robot.spacing))
    beams = int(spec['chain']['beams_per_interval']) if beams is None else int(beams)
    if beams < 1:
        raise ValueError(f'beams must be >= 1, got {beams}')
    with tempfile.TemporaryDirectory() as folder:
        scene = (load_scene(path) if beams == spec['chain']['beams_per_interval']
                 else _scene_with_beams(spec, Path(folder) / 'scene.yaml', beams))
        refined = {f: _scene_with_beams(spec, Path(folder) / f'x{f}.yaml', f * beams)
                   for f in ((2, 4) if refine else ())}
    rows = []
    for case in cases:
        ours = our_tip(scene, case)
        reference = reference_tip(robot, case)
        eyelet = reference_tip(robot, case, 'eyelet')
        row = {'case': case, 'ours': ours, 'reference': reference, 'reference_eyelet': eyelet,
               'error': float(np.linalg.norm(ours - reference)),
               'error_eyelet': float(np.linalg.norm(ours - eyelet)), 'length': length}
        if refine:
            row['refined'] = {f: our_tip(s, case) for f, s in refined.items()}
            # tip(h) = tip(0) + c h^2: the beams' error is of second order in their length
            row['extrapolated'] = (4.0 * row['refined'][4] - row['refined'][2]) / 3.0
        rows.append(row)
    return rows, beams


def _vector(p):
    """Format a position [m] in mm."""
    return '[' + ', '.join(f'{round(1e3 * v, 2) + 0.0:7.2f}' for v in p) + ']'


def format_table(rows, beams):
    """
    Return the benchmark's table as markdown lines.

    Parameters
    ----------
    rows : list of dict
        From :func:`benchmark`.
    beams : int
        The scene's beams per interval.

    Returns
    -------
    list of str

    """
    lines = [f'ours: {beams} Timoshenko beams between disks; reference: Cosserat rod between '
             'disks (Rao et al. 2021), tendon force on a pass-through disk in its plane; '
             '"point contact": that force a frictionless point contact\'s (ours)', '',
             '| case | tensions [N] | tip force [N] | our tip [mm] | reference tip [mm] '
             '| error [mm] | error [% L] | vs point contact [mm] |',
             '|---|---|---|---|---|---|---|---|']
    for row in rows:
        case = row['case']
        tensions = ' '.join(f'{t:g}' for t in case.tensions)
        force = ' '.join(f'{f:g}' for f in case.tip_force)
        lines.append(f"| {case.name} | {tensions} | {force} | {_vector(row['ours'])} "
                     f"| {_vector(row['reference'])} | {1e3 * row['error']:.3f} "
                     f"| {100 * row['error'] / row['length']:.3f} "
                     f"| {1e3 * row['error_eyelet']:.3f} |")
    worst = max(rows, key=lambda r: r['error'])
    lines += ['', f"largest error: {1e3 * worst['error']:.3f} mm "
              f"({100 * worst['error'] / worst['length']:.3f} % of L = "
              f"{1e3 * worst['length']:.0f} mm), case {worst['case'].name}"]
    if 'refined' in rows[0]:
        lines += ['', 'refinement: error against the reference with point contact [mm]', '',
                  f'| case | {beams} beams | {2 * beams} beams | {4 * beams} beams '
                  '| extrapolated | extrapolated vs paper reference |',
                  '|---|---|---|---|---|---|']
        for row in rows:
            eyelet = row['reference_eyelet']
            errors = [row['ours']] + [row['refined'][f] for f in (2, 4)] + [row['extrapolated']]
            cells = ' | '.join(f'{1e3 * np.linalg.norm(p - eyelet):.4f}' for p in errors)
            paper = 1e3 * np.linalg.norm(row['extrapolated'] - row['reference'])
            lines.append(f"| {row['case'].name} | {cells} | {paper:.4f} |")
    return lines


def main(argv=None):
    """
    Solve the benchmark's cases and print the table.

    Parameters
    ----------
    argv : list of str, optional
        Command-line arguments (``sys.argv[1:]`` by default).

    Returns
    -------
    int
        Exit status (0).

    """
    parser = argparse.ArgumentParser(
        prog='cbha_report rao2021',
        description="the package's model against the reference model of Rao et al. 2021 on "
                    'their two-segment tendon robot (docs/benchmark-rao2021.md)')
    parser.add_argument('--scene', default=SCENE,
                        help='scene YAML (a path or a name in config/scenes), default %(default)s')
    parser.add_argument('--cases', nargs='+', choices=[c.name for c in CASES],
                        help='the cases to solve (default: all)')
    parser.add_argument('--beams', type=int,
                        help="Timoshenko beams between two disks (default: the scene's)")
    parser.add_argument('--refine', action='store_true',
                        help='also 2 and 4 times the beams per interval, and their extrapolation')
    args = parser.parse_args(argv)
    if args.beams is not None and args.beams < 1:
        parser.error(f'--beams must be >= 1, got {args.beams}')
    cases = [c for c in CASES if args.cases is None or c.name in args.cases]
    start = time.perf_counter()
    rows, beams = benchmark(args.scene, cases, args.refine, args.beams)
    print('\n'.join(format_table(rows, beams)))
    print(f'\n{len(rows)} cases in {time.perf_counter() - start:.1f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
