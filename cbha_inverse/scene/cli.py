"""
``cbha_scene check SCENE``: what a scene builds, before any node runs it.

Prints the frames, the actuators and their bounds, the effectors at rest (under the scene's
gravity), the reach along each actuator (the tip displacement with that actuator alone at its
upper bound; for an ``axis`` effector the tilt of its axis, for a ``pose`` effector the turn of
its frame, ``docs/effectors.md``), the suggested workspace centre, the inverse solver's tick
time (median and p99 of a run toward the centre) and the reachable set (``--reach-samples``
forward solves, :func:`cbha_inverse.scene.reach.sample_reachable_set`: its box, its centre and
the largest circle around that centre in each principal plane; the tilt or turn of an ``axis``
or ``pose`` effector over the samples). A scene with ``obstacles`` also gets them listed, with
the robot's collision spheres and their minimum clearance to each obstacle at rest (negative:
the rest shape penetrates it; ``docs/obstacles.md``).

``--actuation V ...`` (one value per actuator, N or Pa) or ``--actuation-fraction F`` prints the
equilibrium at that actuation instead: the effectors, the solve's iterations and residual, the
tendons' routed lengths and the string pots' lengths and readings, with their change from rest.
``--load NAME=FX,FY,FZ[,TX,TY,TZ]@FRAME[:base|local]`` (repeatable; ``NAME=KG@FRAME`` for a
mass, FRAME an index or ``tip``) adds a load to the scene's (``docs/loads.md``) and prints the
loaded equilibrium (at ``--actuation``, or at zero actuation) and its move from rest.
``--convergence`` prints how far the effectors move when the chain is refined (at rest, at half
range and at the given actuation; :mod:`cbha_inverse.scene.refinement`). With either, the reach,
tick time and reachable set are skipped. Exit status 0; 1 if a forward solve does not converge;
2 on a bad scene file (one line naming the file and the key) or option.
"""

import argparse
from pathlib import Path
import sys
import time

from cbha_inverse.core.actuation.cables import CableGroup
from cbha_inverse.core.loads import Load
from cbha_inverse.errors import ConfigError, report_config_error
import numpy as np

PROGRAM = 'cbha_scene'
DEFAULT_REACH_SAMPLES = 300
"""Default ``--reach-samples`` (:data:`cbha_inverse.scene.reach.DEFAULT_SAMPLES`)."""
DEFAULT_TOLERANCE_MM = 0.1
"""Default ``--tolerance`` of ``--convergence`` [mm]."""


def _parser():
    parser = argparse.ArgumentParser(prog=PROGRAM, description=__doc__.strip().splitlines()[0])
    commands = parser.add_subparsers(dest='command', required=True)
    commands.add_parser('schema', help='print the scene file reference (docs/scene-schema.md): '
                        'every key, unit, default and convention')
    check = commands.add_parser('check', help='load a scene and report what it builds')
    check.add_argument('scene', help='scene YAML: a path, or a name in config/scenes')
    check.add_argument('--ticks', type=int, default=200, help='solver ticks timed (default 200)')
    check.add_argument('--reach-samples', type=int, default=DEFAULT_REACH_SAMPLES, metavar='N',
                       help='actuations sampled for the reachable set (default '
                            f'{DEFAULT_REACH_SAMPLES}; 0 skips it)')
    given = check.add_mutually_exclusive_group()
    given.add_argument('--actuation', type=float, nargs='+', metavar='V',
                       help='print the equilibrium at this actuation: one value per actuator '
                            'in scene order, N (cables) or Pa (cavities)')
    given.add_argument('--actuation-fraction', type=float, metavar='F',
                       help='print the equilibrium with every actuator at F of its range (0..1)')
    check.add_argument('--load', action='append', metavar='NAME=F@FRAME',
                       help='print the equilibrium with this load added (repeatable): '
                            'NAME=FX,FY,FZ[,TX,TY,TZ]@FRAME[:base|local] (N, N*m; base: '
                            'base-frame axes, the default; local: turns with the frame) or '
                            'NAME=KG@FRAME (a mass); FRAME an index or tip')
    check.add_argument('--convergence', action='store_true',
                       help='print how far the effectors move on a refined chain (beams per '
                            'interval doubled; for segments, the mesh size halved)')
    check.add_argument('--recondense', action='store_true',
                       help='with --convergence on a segments chain: recondense each segment '
                            'at half its mesh size (tens of seconds per segment) instead of '
                            'printing the command')
    check.add_argument('--tolerance', type=float, default=DEFAULT_TOLERANCE_MM, metavar='MM',
                       help='--convergence: effector movement [mm] below which the chain is '
                            f'converged (default {DEFAULT_TOLERANCE_MM:g})')
    return parser


class _BadOption(ValueError):
    """An option value the scene rules out (reported like argparse's own errors)."""


def _millimetres(point, digits=1):
    return '[' + ', '.join(f'{1e3 * v:.{digits}f}' for v in point) + '] mm'


def actuator_units(scene):
    """Return the unit of each actuator in scene order (``N`` for cables, ``Pa`` otherwise)."""
    units = {}
    for group in scene.actuators.groups:
        for name in group.names:
            units[name] = 'N' if isinstance(group, CableGroup) else 'Pa'
    return [units[name] for name in scene.actuator_names]


def reach(scene):
    """
    Return the effector displacement and turn of each actuator alone at its upper bound.

    Parameters
    ----------
    scene : cbha_inverse.scene.Scene
        The scene.

    Returns
    -------
    displacements : (m, k, 3) ndarray  [m]
        Displacement from the rest effector positions, per actuator.
    turns : (m, k) ndarray  [rad]
        Turn from rest of each effector's orientation (:func:`effector_turns`), per actuator.

    Raises
    ------
    RuntimeError
        If a forward solve does not converge.

    """
    rest = scene.forward(np.clip(np.zeros(len(scene.actuator_names)), scene.lower_bounds,
                                 scene.upper_bounds), strict=True)
    rest_rotations = scene.effectors.rotations(rest.rotations)
    moved, turns = [], []
    for index in range(len(scene.actuator_names)):
        actuation = np.array(scene.lower_bounds, dtype=float)
        actuation[index] = scene.upper_bounds[index]
        result = scene.forward(actuation, strict=True)
        moved.append(result.effector_positions - rest.effector_positions)
        turns.append(effector_turns(scene.effectors.kinds, scene.effectors.axes,
                                    rest_rotations,
                                    scene.effectors.rotations(result.rotations)))
    return np.array(moved), np.array(turns)


def effector_turns(kinds, axes, rest, rotations):
    """
    Return how far each effector's orientation turned from rest [rad].

    An ``axis`` effector: the angle between its axis at rest and now (a turn about the axis is
    free); a ``pose`` or ``point`` effector: the angle of its frame's rotation from rest.

    Parameters
    ----------
    kinds : sequence of str
        The effectors' kinds (``k``).
    axes : (k, 3) ndarray
        Their axes in their frames' axes.
    rest, rotations : (..., k, 3, 3) ndarray
        The effectors' frame rotations at rest and now.

    Returns
    -------
    (..., k) ndarray  [rad]

    """
    tilt = np.arccos(np.clip(np.einsum('...kij,kj,...kil,kl->...k', rest, axes, rotations, axes),
                             -1.0, 1.0))
    relative = np.einsum('...kji,...kjl->...kil', rest, rotations)
    turn = np.arccos(np.clip(0.5 * (np.trace(relative, axis1=-2, axis2=-1) - 1.0), -1.0, 1.0))
    return np.where(np.array(kinds) == 'axis', tilt, turn)


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
    index = scene.effector_names.index(reach.effector)
    kind = scene.effectors.kinds[index]
    if kind != 'point':
        turns = np.degrees(effector_turns(
            [kind], scene.effectors.axes[index:index + 1], reach.rotations[:1, None],
            reach.rotations[:, None])[:, 0])
        what = 'axis tilt' if kind == 'axis' else 'orientation turn'
        print(f'  {what} from the lower bounds over the samples: median {np.median(turns):.1f}'
              f' deg, max {turns.max():.1f} deg', file=out)
    return reach


def _circles(radii):
    return ', '.join(f'{plane} {1e3 * radius:.1f} mm' for plane, radius in radii.items())


def given_actuation(scene, values=None, fraction=None):
    """
    Return the actuation of ``--actuation`` or ``--actuation-fraction``, checked.

    Parameters
    ----------
    scene : cbha_inverse.scene.Scene
        The scene.
    values : sequence of float, optional  [N or Pa]
        One value per actuator, in scene order.
    fraction : float, optional
        Every actuator at this fraction of its range (0..1).

    Returns
    -------
    (m,) ndarray or None  [N or Pa]
        None when neither is given.

    Raises
    ------
    ValueError
        (``_BadOption``) On a wrong count, a value outside its actuator's bounds or a fraction
        outside [0, 1], with one line that says which.

    """
    low, high = scene.lower_bounds, scene.upper_bounds
    if fraction is not None:
        if not 0.0 <= fraction <= 1.0:
            raise _BadOption(f'--actuation-fraction must lie in [0, 1], got {fraction:g}')
        return low + fraction * (high - low)
    if values is None:
        return None
    names, units = scene.actuator_names, actuator_units(scene)
    actuation = np.asarray(values, dtype=float)
    if actuation.size != len(names):
        raise _BadOption(f'--actuation needs {len(names)} values, one per actuator '
                         f'({", ".join(names)}), got {actuation.size}')
    outside = [i for i, v in enumerate(actuation) if not low[i] <= v <= high[i]]
    if outside:
        i = outside[0]
        more = f' (and {len(outside) - 1} more)' if len(outside) > 1 else ''
        raise _BadOption(f'--actuation: {names[i]} {actuation[i]:g} {units[i]} is outside its '
                         f'bounds [{low[i]:g}, {high[i]:g}] {units[i]}{more}')
    return actuation


def given_loads(scene, specs):
    """
    Return the scene's loads with those of ``--load`` added (None without ``--load``).

    Parameters
    ----------
    scene : cbha_inverse.scene.Scene
        The scene.
    specs : list of str or None
        ``NAME=FX,FY,FZ[,TX,TY,TZ]@FRAME[:base|local]`` or ``NAME=KG@FRAME``.

    Returns
    -------
    cbha_inverse.core.loads.Loads or None

    Raises
    ------
    ValueError
        (``_BadOption``) On a load that does not parse or does not fit the scene, with one line
        that says which.

    """
    if not specs:
        return None
    loads = scene.loads
    for spec in specs:
        try:
            loads = loads.updated(_parsed_load(spec)).checked(scene.model.n_links, scene.gravity)
        except ValueError as exc:
            raise _BadOption(f'--load {spec}: {exc}') from None
    return loads


def _parsed_load(spec):
    """Return the :class:`~cbha_inverse.core.loads.Load` of one ``--load`` (ValueError if bad)."""
    name, equals, rest = spec.partition('=')
    if not equals or not name:
        raise ValueError('expected NAME=VALUES@FRAME')
    values, at, where = rest.partition('@')
    if not at:
        raise ValueError('expected @FRAME after the values (an index or tip)')
    frame, _, axes = where.partition(':')
    if axes not in ('', 'base', 'local'):
        raise ValueError(f'axes must be base or local, got {axes!r}')
    try:
        numbers = [float(v) for v in values.split(',')]
        frame = frame if frame == 'tip' else int(frame)
    except ValueError:
        raise ValueError('values must be numbers and FRAME an index or tip') from None
    if len(numbers) not in (1, 3, 6):
        raise ValueError(f'give 1 (a mass, kg), 3 or 6 values, got {len(numbers)}')
    if not np.all(np.isfinite(numbers)):
        raise ValueError('values must be finite')
    if len(numbers) == 1:
        if axes:
            raise ValueError('a mass takes no axes')
        return Load.of_mass(name, frame, numbers[0])
    return Load.of_wrench(name, frame, numbers[:3], (numbers + [0.0] * 3)[3:6], axes or 'base')


def _actuation_text(actuation, units):
    values = ', '.join(f'{v:g}' for v in actuation)
    if len(set(units)) == 1:
        return f'[{values}] {units[0]}'
    return '[' + ', '.join(f'{v:g} {u}' for v, u in zip(actuation, units)) + ']'


def print_equilibrium(scene, actuation, out, loads=None):
    """
    Solve the equilibrium at an actuation and print it (``--actuation``, ``--load``).

    The loads added, the effectors, the solve (converged, iterations, load steps, residual),
    the routed length of each tendon and the length and raw reading of each string pot, with
    their change from rest (zero actuation, under the scene's gravity and loads; pulled in:
    negative).

    Parameters
    ----------
    scene : cbha_inverse.scene.Scene
        The scene.
    actuation : (m,) ndarray  [N or Pa]
        Within the bounds (:func:`given_actuation`).
    out : file-like
        Where the lines go.
    loads : cbha_inverse.core.loads.Loads, optional
        The loads of the equilibrium (:func:`given_loads`; default: the scene's).

    Returns
    -------
    int
        0, or 1 if the solve did not converge.

    Raises
    ------
    RuntimeError
        If the rest solve does not converge.

    """
    low, high = scene.lower_bounds, scene.upper_bounds
    rest = scene.forward(np.clip(np.zeros_like(low), low, high), strict=True)
    result = scene.forward(actuation, loads=loads)
    units = actuator_units(scene)
    print(f'equilibrium at {_actuation_text(actuation, units)}:', file=out)
    for item in () if loads is None else loads.items:
        if item in scene.loads.items:
            continue
        what = (f'{item.mass:g} kg' if item.mass else
                f'force [{", ".join(f"{v:g}" for v in item.wrench[:3])}] N, torque '
                f'[{", ".join(f"{v:g}" for v in item.wrench[3:])}] N*m in {item.axes} axes')
        print(f'  load {item.name}: {what} at frame '
              f'{item.frame_index(scene.model.n_links)}', file=out)
    steps = f'{result.load_steps} load step' + ('s' if result.load_steps != 1 else '')
    verdict = ('converged' if result.converged else
               f'NOT converged ({result.message}), load factor {result.load_factor:g}')
    print(f'  {verdict}: {result.iterations} iterations ({steps}), residual '
          f'{result.residual_norm:.2g} N', file=out)
    for warning in result.warnings:
        print(f'  warning: {warning}', file=out)
    for name, point, at_rest in zip(scene.effector_names, result.effector_positions,
                                    rest.effector_positions):
        moved = point - at_rest
        print(f'  effector {name}: {_millimetres(point, 3)}, from rest {_millimetres(moved, 3)}'
              f' |{1e3 * np.linalg.norm(moved):.3f} mm|', file=out)
    if 'N' in units:
        names, lengths, _ = scene.cable_lengths(result.state)
        _, rest_lengths, _ = scene.cable_lengths(rest.state)
        print('tendon lengths (routed; change from rest, pulled in: negative):', file=out)
        for name, length, change in zip(names, lengths, lengths - rest_lengths):
            print(f'  {name}: {1e3 * length:.3f} mm ({1e3 * change:+.3f} mm)', file=out)
    pots = scene.sensors
    if pots is not None:
        lengths = pots.lengths(result.state.positions, result.state.rotations)
        changes = lengths - pots.lengths(rest.state.positions, rest.state.rotations)
        print('string pots (length, change from rest; raw reading):', file=out)
        for name, length, change, reading in zip(pots.names, lengths, changes,
                                                 pots.readings(lengths)):
            print(f'  {name}: {1e3 * length:.3f} mm ({1e3 * change:+.3f} mm); reading '
                  f'{reading:.6g}', file=out)
    return 0 if result.converged else 1


def print_convergence(scene, actuation, out, recondense=False,
                      tolerance_mm=DEFAULT_TOLERANCE_MM):
    """
    Refine the scene's chain and print how far its effectors move (``--convergence``).

    A ``beam_vertebrae`` chain doubles ``beams_per_interval``; a ``segments`` chain halves the
    mesh size of its segments, recondensed only with ``recondense`` (else the commands are
    printed). Solved at rest, at half range and at ``actuation``
    (:mod:`cbha_inverse.scene.refinement`).

    Parameters
    ----------
    scene : cbha_inverse.scene.Scene
        The scene, loaded from ``scene.path``.
    actuation : (m,) ndarray or None  [N or Pa]
        One more actuation to compare at.
    out : file-like
        Where the lines go.
    recondense : bool
        Recondense the segments of a ``segments`` chain.
    tolerance_mm : float  [mm]
        Movement below which the chain is converged.

    Returns
    -------
    int
        0, or 1 if a forward solve did not converge.

    """
    import tempfile
    from cbha_inverse.scene import refinement
    data = refinement.scene_data(scene.path)
    labels, actuations = refinement.representative_actuations(scene, actuation)
    started = time.perf_counter()
    if data['chain']['type'] == 'beam_vertebrae':
        refined, change = refinement.refined_beam_scene(scene.path)
    else:
        sources = refinement.segment_sources(scene.path, data)
        print('segments to recondense at half their mesh size:', file=out)
        for source in sources:
            geometry = ('not found (no YAML next to the scene or the segment has the '
                        'inputs_sha256 it stores)' if source.geometry is None
                        else refinement.shown(source.geometry))
            print(f'  {refinement.shown(source.segment)} (sections {", ".join(source.sections)}): '
                  f'P{source.order}, mesh size {1e3 * source.mesh_size:g} mm, condensed in '
                  f'{source.seconds:.1f} s; geometry {geometry}', file=out)
        if not recondense or any(source.geometry is None for source in sources):
            for index, source in enumerate(sources):
                print(f'  {source.command(Path(f"fine_{index}", source.segment.name))}', file=out)
            why = ('a geometry file was not found' if recondense else
                   'each segment takes several times its condensation time at half the mesh '
                   'size; --recondense runs them')
            print(f'convergence: not checked ({why}): run the commands above and check a copy '
                  'of the scene that names the fine segments', file=out)
            return 0
        with tempfile.TemporaryDirectory(prefix='cbha_recondense_') as folder:
            try:
                refined = refinement.load_data(
                    refinement.recondensed_data(scene.path, data, sources, folder, out),
                    folder, scene.path.name)
            except (OSError, ValueError, RuntimeError) as exc:
                # a geometry gmsh cannot mesh at the finer size, a full disk: one line
                print(f'convergence: not checked (recondensing failed: '
                      f'{str(exc).splitlines()[0] if str(exc) else type(exc).__name__})',
                      file=out)
                return 1
        change = ('mesh_size', ', '.join(f'{1e3 * s.mesh_size:g}' for s in sources) + ' mm',
                  ', '.join(f'{1e3 * s.fine_mesh_size:g}' for s in sources) + ' mm')
    comparison = refinement.compare(scene, refined, change, labels, actuations)
    took = time.perf_counter() - started
    print(f'convergence: {comparison.refinement} ({took:.2f} s)', file=out)
    for label, moved, solved in zip(comparison.labels, comparison.movement,
                                    comparison.converged):
        print(f'  {label}: ' + '; '.join(f'{name} moves {1e3 * m:.3f} mm' for name, m in zip(
            scene.effector_names, moved)) + ('' if solved.all() else ' (not converged)'),
              file=out)
    print(f'  {refinement.recommendation(comparison, 1e-3 * tolerance_mm)}', file=out)
    return 0 if comparison.converged.all() else 1


def check(scene_path, ticks, out, reach_samples=DEFAULT_REACH_SAMPLES, *, actuation=None,
          actuation_fraction=None, convergence=False, recondense=False,
          tolerance_mm=DEFAULT_TOLERANCE_MM, loads=None):
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
    actuation : sequence of float, optional  [N or Pa]
        Print the equilibrium at this actuation (:func:`print_equilibrium`) instead of the
        reach, tick time and reachable set.
    actuation_fraction : float, optional
        As ``actuation``, every actuator at this fraction of its range.
    convergence : bool
        Print the discretisation check (:func:`print_convergence`) instead of the reach, tick
        time and reachable set.
    recondense : bool
        With ``convergence``: recondense the segments of a ``segments`` chain.
    tolerance_mm : float  [mm]
        With ``convergence``: movement below which the chain is converged.
    loads : list of str, optional
        ``--load`` specifications (:func:`given_loads`): print the equilibrium with them added
        (at ``actuation``, or at zero actuation).

    Returns
    -------
    int
        0 (1 if a forward solve does not converge).

    Raises
    ------
    ValueError
        If ``reach_samples`` is neither 0 nor enough for the scene's actuators, or the
        actuation is of the wrong count or outside the bounds.

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
    given = given_actuation(scene, actuation, actuation_fraction)
    with_loads = given_loads(scene, loads)
    if with_loads is not None and given is None:
        given = np.clip(np.zeros(len(scene.actuator_names)), scene.lower_bounds,
                        scene.upper_bounds)
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
    if scene.obstacles:
        try:
            print_clearance(scene, out)
        except RuntimeError as exc:
            print(f'error: {exc}', file=out)
            return 1
    if given is not None or convergence:
        try:
            status = 0 if given is None else print_equilibrium(scene, given, out, with_loads)
            if convergence:
                status = max(status, print_convergence(scene, given, out, recondense,
                                                       tolerance_mm))
        except RuntimeError as exc:
            print(f'error: {exc}', file=out)
            return 1
        return status
    try:
        rest = scene.rest_effector_positions
        displacements, turns = reach(scene)
    except RuntimeError as exc:
        print(f'error: {exc}', file=out)
        return 1
    for name, point in zip(scene.effector_names, rest):
        print(f'effector {name} at rest: {_millimetres(point)}', file=out)
    print('reach (effector displacement, each actuator alone at its upper bound):', file=out)
    kinds = scene.effectors.kinds
    for name, moved, turned in zip(scene.actuator_names, displacements, turns):
        print(f'  {name}: ' + '; '.join(
            f'{effector} {_millimetres(d)} |{1e3 * np.linalg.norm(d):.1f} mm|'
            + ('' if kind == 'point' else
               f' {"tilt" if kind == "axis" else "turn"} {np.degrees(turn):.1f} deg')
            for effector, d, turn, kind in zip(scene.effector_names, moved, turned, kinds)),
            file=out)
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


def print_clearance(scene, out):
    """
    Print the scene's obstacles and the minimum clearance of its collision spheres at rest.

    The rest shape is the free equilibrium at zero actuation (clipped to the bounds) under the
    scene's gravity, the obstacles left out; the clearance of a sphere is the signed distance of
    its centre to the obstacle minus its radius
    (:meth:`cbha_inverse.core.contact.CollisionSpheres.clearances`).

    Parameters
    ----------
    scene : cbha_inverse.scene.Scene
        A scene with obstacles (and so with collision spheres).
    out : file-like
        Where the lines go.

    Raises
    ------
    RuntimeError
        If the rest shape does not converge.

    """
    spheres = scene.collision
    rest = scene.forward(np.clip(np.zeros(len(scene.actuator_names)), scene.lower_bounds,
                                 scene.upper_bounds), strict=True, check_warnings=False)
    radii = np.unique(spheres.radii)
    print(f'collision: {spheres.frames.size} spheres at frames {spheres.frames[0]}..'
          f'{spheres.frames[-1]}, radius ' + ', '.join(f'{1e3 * r:.1f}' for r in radii)
          + ' mm', file=out)
    gaps = spheres.clearances(rest.positions, scene.obstacles)
    print(f'obstacles: {len(scene.obstacles)}', file=out)
    for column, obstacle in enumerate(scene.obstacles):
        nearest = int(np.argmin(gaps[:, column]))
        print(f'  {obstacle.describe()}; clearance at rest {1e3 * gaps[nearest, column]:.1f} mm '
              f'(frame {spheres.frames[nearest]})', file=out)
    sphere, column = np.unravel_index(np.argmin(gaps), gaps.shape)
    least = gaps[sphere, column]
    print(f'minimum clearance at rest: {1e3 * least:.1f} mm (frame {spheres.frames[sphere]} to '
          f'{scene.obstacles[column].name})'
          + (': the rest shape penetrates it' if least < 0.0 else ''), file=out)


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
    if args.command == 'schema':
        from cbha_inverse.scene.schema import markdown
        sys.stdout.write(markdown())
        return 0
    if args.recondense and not args.convergence:
        parser.error('--recondense needs --convergence')
    if not args.tolerance > 0.0:
        parser.error(f'--tolerance must be > 0 mm, got {args.tolerance:g}')
    try:
        return check(args.scene, args.ticks, sys.stdout, args.reach_samples,
                     actuation=args.actuation, actuation_fraction=args.actuation_fraction,
                     convergence=args.convergence, recondense=args.recondense,
                     tolerance_mm=args.tolerance, loads=args.load)
    except (ConfigError, FileNotFoundError) as exc:
        return report_config_error(PROGRAM, exc)
    except _BadOption as exc:
        parser.error(str(exc))


if __name__ == '__main__':
    sys.exit(main())
