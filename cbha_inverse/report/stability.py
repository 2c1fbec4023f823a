"""
``cbha_report stability``: numerical stability on stiff and extreme cases.

One row per case: what is checked (residual, condition or reference, no NaN, bounds), the
answer against an independent reference (:mod:`cbha_inverse.report.references`, closed forms,
FEM of the same body), pass/fail and the message the user gets. A case passes when the answer
is right, or when the user is told (a warning, a refusal, a non-converged result with its
message): no case may return success with a wrong answer. Writes ``stability.md``,
``stability.json`` and ``stability.png`` to ``--output`` (default ``output/report``).

The results and how to read them: docs/stability-and-accuracy.md.
"""

import argparse
from dataclasses import asdict, dataclass, field, replace
import json
import math
from pathlib import Path
import platform
import sys
import time
import tracemalloc

from cbha_inverse.core.actuation.actuators import ActuatorSet
from cbha_inverse.core.actuation.cables import CableGroup
from cbha_inverse.core.inverse.solver import InverseSolver
from cbha_inverse.core.linalg.btd import factorize
from cbha_inverse.core.links import timoshenko_compliance
from cbha_inverse.core.statics import solve_static
from cbha_inverse.core.system import EquilibriumSystem
from cbha_inverse.errors import ConfigError
from cbha_inverse.paths import config_path
from cbha_inverse.report.references import (elastica_tip, linear_tip_displacement,
                                            straight_beam_chain)
from cbha_inverse.scene import load_scene
import numpy as np
import yaml

E_MOD, NU, RADIUS = 2.0e9, 0.3, 0.005


@dataclass
class Case:
    """One row of the report: what was checked, the numbers, pass/fail, the user's message."""

    group: str
    name: str
    checked: str
    passed: bool
    error: float = float('nan')
    message: str = ''
    values: dict = field(default_factory=dict)


def _told(warnings):
    """Join warnings for the message column."""
    return '; '.join(warnings) if warnings else 'no warning'


def _outcome(res):
    """Return the user's message of a static result: its warnings, or why it did not converge."""
    return _told(res.warnings) if res.converged else res.message


def _condition(model, state):
    """Return the 1-norm condition estimate of the tangent at a state (BTD Cholesky)."""
    system = EquilibriumSystem(model, ActuatorSet((), model.n_frames), np.zeros(6 * model.n_links))
    tangent, _ = system.linearise(state.positions, state.rotations, np.zeros(0))
    return float(factorize(*system.tridiagonal_blocks(tangent)).condition_estimate)


def _small_tip_force(compliances, offsets, deflection):
    """Tip force along +y [N] whose linear tip deflection is ``deflection`` [m]."""
    unit = linear_tip_displacement(compliances, offsets, np.array([0.0, 1.0, 0, 0, 0, 0]))
    return np.array([0.0, deflection / np.linalg.norm(unit), 0.0, 0.0, 0.0, 0.0])


def stiffness_cases(quick):
    """
    Stiffness ratios 1e-9..1e9 on one link, between halves and on the tip link.

    The tip force deflects each chain by 1e-5 of its length (a small load: the linear
    flexibility is then the reference to ~1e-5).
    """
    exponents = (-9, -6, -3, 0, 3, 6, 9) if quick else tuple(range(-9, 10))
    cases = []
    for kind in ('one link', 'half chain', 'tip link'):
        for exponent in exponents:
            factors = np.ones(10)
            if kind == 'one link':
                factors[5] = 10.0 ** exponent
            elif kind == 'half chain':
                factors[5:] = 10.0 ** exponent
            else:
                factors[9] = 10.0 ** exponent
            model, comp, offsets = straight_beam_chain(10, 0.1, E_MOD, NU, RADIUS, factors)
            wrench = _small_tip_force(comp, offsets, 1e-6)
            res = solve_static(model, tip_wrench=wrench)
            ref = linear_tip_displacement(comp, offsets, wrench)
            err = float(np.linalg.norm(res.positions[-1] - offsets.sum(0) - ref)
                        / np.linalg.norm(ref))
            ok = res.converged and np.all(np.isfinite(res.positions)) and err < 1e-4
            condition = _condition(model, res.state)
            cases.append(Case('stiffness ratio', f'{kind} x 1e{exponent:+d}',
                              'converged, tip vs linear chain flexibility (1e-4); condition '
                              'estimate of the tangent', bool(ok), err,
                              f'{_outcome(res)} (condition {condition:.1e})',
                              {'exponent': exponent, 'kind': kind,
                               'iterations': res.iterations, 'condition': condition,
                               'residual_over_load': res.residual_norm / wrench[1]}))
    return cases


def poisson_cases(quick):
    """
    Poisson ratios 0.45..0.49999 for P1 and P2 on a cylinder (L 40 mm, R 10 mm): locking.

    Torsion of a circular cylinder is exact in beam theory whatever the end faces, so its
    compliance ratio to ``L / GJ`` isolates locking; the check compares it with the same mesh at
    nu = 0.3 (which removes the plain discretisation error of coarse P1). The bending ratio is
    reported (its trend shows P2's milder locking).
    """
    from cbha_inverse.fem.condensation import condense_cylinder
    ratios = ((0.45, 0.49, 0.499, 0.4999) if quick
              else (0.45, 0.47, 0.49, 0.495, 0.499, 0.4999, 0.49999))
    length, radius = 0.04, 0.01
    sizes = {1: 0.003, 2: 0.006} if quick else {1: 0.002, 2: 0.004}
    cases = []
    for order in (1, 2):
        base = None
        for nu in (0.3,) + ratios:
            seg = condense_cylinder(length, radius, youngs_modulus=1e6, poisson_ratio=nu,
                                    mesh_size=sizes[order], order=order)
            reference = timoshenko_compliance(length, 1e6, nu, radius)
            ratio = np.diag(seg.compliance) / np.diag(reference)
            if base is None:
                base = ratio
                continue
            err = float(abs(ratio[3] / base[3] - 1.0))
            ok = bool(np.all(np.isfinite(seg.compliance)) and (err < 0.05 or seg.warnings))
            cases.append(Case('Poisson ratio', f'P{order} nu={nu:g}',
                              'torsion compliance vs the same mesh at nu = 0.3 (5 %) or a '
                              'warning', ok, err, _told(seg.warnings),
                              {'order': order, 'nu': nu, 'torsion_ratio': float(ratio[3]),
                               'bending_ratio': float(ratio[5]),
                               'bending_vs_nu03': float(ratio[5] / base[5]),
                               'time_s': seg.timings.get('total', float('nan'))}))
    return cases


def length_cases(quick):
    """Chains of 10 links 1 mm .. 10 m long under a load deflecting them by 1e-4 L."""
    lengths = (1e-3, 1e-1, 10.0) if quick else (1e-3, 1e-2, 1e-1, 1.0, 10.0)
    cases = []
    for length in lengths:
        model, comp, offsets = straight_beam_chain(10, length, E_MOD, NU, RADIUS * length / 0.1)
        tip = timoshenko_compliance(length, E_MOD, NU, RADIUS * length / 0.1)
        force = 1e-4 * length / tip[1, 1]
        wrench = np.array([0.0, force, 0.0, 0.0, 0.0, 0.0])
        res = solve_static(model, tip_wrench=wrench)
        ref = linear_tip_displacement(comp, offsets, wrench)
        err = float(np.linalg.norm(res.positions[-1] - offsets.sum(0) - ref)
                    / np.linalg.norm(ref))
        cases.append(Case('segment length', f'L = {length:g} m',
                          'converged, tip vs linear flexibility (1e-3)',
                          bool(res.converged and err < 1e-3), err, _outcome(res),
                          {'length': length, 'iterations': res.iterations}))
    return cases


def frame_count_cases(quick):
    """10..10,000 frames under a small tip force: time, residual, memory, vs whole beam."""
    counts = (10, 100, 1000) if quick else (10, 100, 1000, 10000)
    cases = []
    for n in counts:
        model, _, _ = straight_beam_chain(n, 1.0, E_MOD, NU, RADIUS)
        whole = timoshenko_compliance(1.0, E_MOD, NU, RADIUS)
        wrench = np.array([0.0, 1e-3 / whole[1, 1], 0.0, 0.0, 0.0, 0.0])   # 1 mm deflection
        started = time.perf_counter()
        res = solve_static(model, tip_wrench=wrench)
        elapsed = time.perf_counter() - started
        # memory in a second solve: tracing allocations slows the solve down several times
        tracemalloc.start()
        solve_static(model, tip_wrench=wrench)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        err = abs(res.positions[-1, 1] - 1e-3) / 1e-3
        cases.append(Case('frames', f'{n} frames', 'converged, tip vs whole-beam Timoshenko '
                          '(geometric nonlinearity at 1e-3 deflection: 1e-3)',
                          bool(res.converged and err < 1e-3), float(err), _outcome(res),
                          {'frames': n, 'time_s': elapsed, 'peak_memory_mb': peak / 1e6,
                           'residual_norm': res.residual_norm, 'iterations': res.iterations}))
    return cases


def rollup_cases(quick):
    """Tip moment 2 pi k EI / L (k = 1, 2 full turns): every frame on the exact circle."""
    n = 64 if quick else 128
    cases = []
    for turns in (1, 2):
        model, comp, offsets = straight_beam_chain(n, 0.1, E_MOD, NU, RADIUS)
        bending = 0.1 / comp[:, 5, 5].sum()
        curvature = 2.0 * np.pi * turns / 0.1
        res = solve_static(model, tip_wrench=[0.0, 0.0, 0.0, 0.0, 0.0, bending * curvature])
        s = np.arange(n + 1) * 0.1 / n
        exact = np.stack([np.sin(curvature * s), 1.0 - np.cos(curvature * s)], 1) / curvature
        err = float(np.abs(res.positions[:, :2] - exact).max() / 0.1)
        ok = res.converged and (err < 1e-2 or bool(res.warnings))
        cases.append(Case('roll-up', f'{turns} full turn(s), {n} links',
                          'converged, frames on the exact circle (1 % of L) or a warning',
                          bool(ok), err, _outcome(res),
                          {'turns': turns, 'iterations': res.iterations,
                           'load_steps': res.load_steps}))
    return cases


def load_cases(quick):
    """
    Transverse tip loads up to 1e6 EI/L^2 on a slender rod (L/R = 200).

    Up to 1e2 EI/L^2 the axial strain stays below 1e-3 and the inextensible elastica is the
    reference; beyond, the links are strained past their small-strain range and the user must be
    told (a warning or a non-converged result), never given a silent answer.
    """
    alphas = (1.0, 1e2, 1e4, 1e6) if quick else (1.0, 10.0, 1e2, 1e3, 1e4, 1e5, 1e6)
    cases = []
    for alpha in alphas:
        model, comp, _ = straight_beam_chain(40, 0.1, E_MOD, NU, 0.1 / 200)
        bending = 0.1 / comp[:, 5, 5].sum()
        res = solve_static(model, tip_wrench=[0.0, alpha * bending / 0.01, 0.0, 0.0, 0.0, 0.0])
        finite = bool(np.all(np.isfinite(res.positions)))
        if alpha <= 1e2:
            err = float(np.linalg.norm(res.positions[-1, :2] / 0.1 - elastica_tip(alpha)))
            ok = res.converged and finite and err < 2e-2
            checked = 'converged, tip vs exact elastica (2 % of L)'
        else:
            err = float('nan')
            ok = finite and (not res.converged or bool(res.warnings))
            checked = "no NaN; beyond the links' strain range: a warning or non-convergence"
        cases.append(Case('large load', f'P = {alpha:g} EI/L^2', checked, bool(ok), err,
                          _outcome(res),
                          {'alpha': alpha, 'converged': res.converged,
                           'iterations': res.iterations}))
    return cases


def buckling_cases(quick):
    """Axial compression at 0.8 and 1.3 times Euler's load: the second is flagged unstable."""
    cases = []
    for factor in (0.8, 1.3, 3.0):
        model, comp, _ = straight_beam_chain(10, 0.2, E_MOD, NU, RADIUS)
        critical = np.pi ** 2 * (0.2 / comp[:, 5, 5].sum()) / (4.0 * 0.2 ** 2)
        res = solve_static(model, tip_wrench=[-factor * critical, 0.0, 0.0, 0.0, 0.0, 0.0])
        unstable = any('unstable' in text for text in res.warnings)
        ok = res.converged and unstable == (factor > 1.0)
        cases.append(Case('buckling', f'compression {factor:g} P_cr',
                          'straight equilibrium; unstable warning iff above Euler P_cr',
                          bool(ok), float('nan'), _outcome(res), {'factor': factor}))
    return cases


def _scene_with(tmp_dir, edit):
    """Load tendon_6f_8c after ``edit(spec)`` (written to a temporary YAML)."""
    spec = yaml.safe_load(config_path('scenes', 'tendon_6f_8c.yaml').read_text(
        encoding='utf-8'))
    edit(spec)
    path = Path(tmp_dir) / 'scene.yaml'
    path.write_text(yaml.safe_dump(spec), encoding='utf-8')
    return load_scene(path)


def _track(solver, target, ticks=30):
    """Tick toward a target; return the last result."""
    out = None
    for _ in range(ticks):
        out = solver.step(target)
    return out


def equilibrium_offset(scene, tick, state):
    """
    Return how far a tick's effectors are from the model's equilibrium at its command.

    Parameters
    ----------
    scene : cbha_inverse.scene.Scene
        The solver's scene.
    tick : cbha_inverse.core.inverse.results.TickResult
        The tick.
    state : cbha_inverse.core.chain.ChainState
        The solver's state right after the tick (the forward solve's warm start).

    Returns
    -------
    offset : float  [m]
        The largest effector distance from the forward solve of ``tick.actuation`` (NaN when
        that solve did not converge).
    forward : cbha_inverse.core.statics.StaticResult
        The forward solve.

    """
    forward = scene.forward(tick.actuation, initial_state=state, check_warnings=False)
    if not forward.converged:
        return math.nan, forward
    return float(np.linalg.norm(forward.effector_positions - tick.effector_positions,
                                axis=1).max()), forward


def _bounded(solver, out):
    """Whether a tick's actuation is finite and within the bounds."""
    return bool(np.all(np.isfinite(out.actuation)) and np.all(out.actuation >= solver.lower_bounds)
                and np.all(out.actuation <= solver.upper_bounds))


def _zero_range_solver(scene):
    """
    Return an inverse solver of ``scene`` whose second cable has zero range.

    A scene file refuses ``max_tension: 0`` (a ConfigError naming the key); the core solver,
    given such an actuator set directly, fixes the actuator at its bound.
    """
    cables = list(scene.actuators.groups[0].cables)
    cables[1] = replace(cables[1], max_tension=0.0)
    actuators = ActuatorSet([CableGroup(cables, scene.model.n_frames)], scene.model.n_frames)
    return InverseSolver(scene.model, actuators, scene.effectors, gravity=scene.gravity,
                         loads=scene.loads)


def actuator_cases(tmp_dir):
    """Redundant (coincident) and zero-range actuators: semi-definite QP; zero range in a file."""
    def duplicate(spec):
        twin = dict(spec['cables'][0])
        twin['name'] = 'tip_0_twin'
        spec['cables'].append(twin)

    def zero_range(spec):
        spec['cables'][1]['max_tension'] = 0.0

    cases = []
    base = load_scene('tendon_6f_8c')
    for name, scene, check in (('coincident cables', _scene_with(tmp_dir, duplicate),
                                'twins share the tension'),
                               ('zero-range cable (core API)', base, 'fixed at 0')):
        solver = (scene.make_inverse_solver() if name == 'coincident cables'
                  else _zero_range_solver(scene))
        m = len(scene.actuator_names)
        actuation = np.zeros(m)
        actuation[[0, 2, 4]] = [3.0, 1.0, 1.0]
        target = scene.forward(actuation).effector_positions
        out = _track(solver, target)
        err = float(np.linalg.norm(out.effector_positions - target))
        if name == 'coincident cables':
            extra = abs(out.actuation[0] - out.actuation[-1]) < 1e-6 * solver.upper_bounds[0]
        else:
            extra = out.actuation[1] == 0.0
        ok = _bounded(solver, out) and err < 1e-6 and extra
        cases.append(Case('actuators', name, f'bounded, target reached (1 um), {check}',
                          bool(ok), err, _told(solver.warnings + out.warnings),
                          {'status': out.status}))
    try:
        _scene_with(tmp_dir, zero_range)
        message, ok = 'accepted', False
    except ConfigError as exc:
        message, ok = str(exc), 'max_tension' in str(exc) and '\n' not in str(exc)
    cases.append(Case('actuators', 'zero-range cable (scene file)',
                      'refused at load: one line naming the file and the key', ok,
                      float('nan'), message, {}))
    return cases


def target_cases():
    """Unreachable, huge, NaN/inf and wrong-shape targets; saturated CBHA pressures."""
    scene = load_scene('tendon_6f_8c')
    sane = scene.forward(np.full(8, 2.0)).effector_positions
    cases = []
    for name, target in (('unreachable (1 m away)', sane + [0.0, 1.0, 0.0]),
                         ('huge (1e308 per axis)', np.full((1, 3), 1e308)),
                         ('NaN', np.full((1, 3), np.nan)), ('inf', np.full((1, 3), np.inf))):
        solver = scene.make_inverse_solver()
        out = _track(solver, target, 30)
        back = _track(solver, sane, 80)
        recovered = float(np.linalg.norm(back.effector_positions - sane))
        ok = _bounded(solver, out) and out.status in ('unreachable', 'rejected') and (
            recovered < 1e-6)
        cases.append(Case('targets', name, 'bounded, unreachable or rejected; next sane target '
                          'reached (1 um)', bool(ok), recovered,
                          f'status {out.status}; ' + _told(out.warnings), {}))
    solver = scene.make_inverse_solver()
    for name, target in (('wrong shape (3, 1)', np.zeros((3, 1))),
                         ('wrong length (4,)', np.zeros(4))):
        try:
            solver.step(target)
            message, ok = 'accepted', False
        except ValueError as exc:
            message, ok = str(exc), True
        cases.append(Case('targets', name, 'refused with a ValueError naming the shape', ok,
                          float('nan'), message, {}))
    cbha = load_scene('cbha')
    solver = cbha.make_inverse_solver()
    far = cbha.workspace_center + [0.0, 0.5, 0.5]
    out = _track(solver, far, 20)
    ok = _bounded(solver, out) and out.status == 'unreachable'
    cases.append(Case('targets', 'CBHA saturated pressures (0.7 m away)',
                      'pressures within [0, p_max], status unreachable', bool(ok), float('nan'),
                      f'status {out.status}, pressures {np.round(out.actuation / 1e3, 1)} kPa',
                      {}))
    return cases


CLEARANCE_SLACK = 5e-4
"""How far [m] below the obstacle margin the model's collision spheres may end (the rows'
linearisation error over a tick)."""


def _model_clearance(scene, solver, obstacles):
    """Return the smallest gap [m] of the model's collision spheres to ``obstacles``."""
    return float(scene.collision.clearances(solver.state.positions, obstacles).min())


def contact_cases():
    """
    Obstacles in the inverse (``cbha_table``): deep targets, a moving obstacle, a pinch, margin 0.

    Each case ticks the model open loop and checks that every command is finite and within its
    bounds, and either that the model keeps the margin (less :data:`CLEARANCE_SLACK`) or that
    the tick says ``obstacle`` (the constraints cannot all hold). A NaN obstacle is refused
    at the door with a message naming the value.
    """
    from cbha_inverse.core.obstacles import Obstacle
    scene = load_scene('cbha_table')
    rest = scene.rest_effector_positions[0]
    cases = []

    def run(name, solver, targets, obstacles, checked, expect):
        outs = []
        for target in targets:
            outs.append(solver.step(np.asarray(target)[None]))
        bounded = all(_bounded(solver, out) for out in outs)
        clearance = _model_clearance(scene, solver, obstacles)
        statuses = sorted({out.status for out in outs})
        margin = solver.options.obstacle_margin
        kept = clearance >= margin - CLEARANCE_SLACK
        ok = bounded and (kept if expect == 'clear' else 'obstacle' in statuses)
        cases.append(Case('contact', name, checked, bool(ok), clearance,
                          f'statuses {statuses}; min clearance {1e3 * clearance:.2f} mm; '
                          + _told(outs[-1].warnings), {'statuses': statuses}))

    deep = rest + [0.0, 0.0, -0.12]          # 40 mm into the table under the arm
    run('target 40 mm inside the table', scene.make_inverse_solver(), [deep] * 60,
        scene.obstacles, 'bounded; the model keeps the margin', 'clear')
    run('target inside the table, margin 0', scene.make_inverse_solver(obstacle_margin=0.0),
        [deep] * 60, scene.obstacles, 'bounded; the model keeps clear of the table', 'clear')
    solver = scene.make_inverse_solver()
    for _ in range(20):
        solver.step(rest[None])
    tip = solver.effector_positions()[0]
    held, bounded, statuses = [], True, set()
    for step in range(30):             # a ball sweeping across the tip, 2 mm per tick
        ball = Obstacle('ball', 'sphere', tip + [0.0, 0.06 - 0.002 * step, 0.0], np.eye(3),
                        radius=0.01)
        obstacles = [*scene.obstacles, ball]
        solver.set_obstacles(obstacles)
        out = solver.step(rest[None])
        bounded &= _bounded(solver, out)
        statuses.add(out.status)
        held.append(out.status == 'obstacle' or _model_clearance(scene, solver, obstacles)
                    >= solver.options.obstacle_margin - CLEARANCE_SLACK)
    clearance = _model_clearance(scene, solver, obstacles)
    cases.append(Case('contact', 'obstacle moving into the arm (2 mm per tick)',
                      'bounded; every tick keeps the margin or says obstacle',
                      bool(bounded and all(held)), clearance,
                      f'statuses {sorted(statuses)}; {held.count(False)} ticks off; last '
                      f'clearance {1e3 * clearance:.2f} mm', {'statuses': sorted(statuses)}))
    pinch = [Obstacle(f'jaw_{side}', 'plane', tip + [0.0, side * 0.01, 0.0],
                      np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -side], [0.0, side, 0.0]]))
             for side in (1.0, -1.0)]
    solver = scene.make_inverse_solver()
    for _ in range(20):
        solver.step(rest[None])
    solver.set_obstacles(pinch)
    run('two planes pinching the tip (20 mm gap)', solver, [rest] * 10, pinch,
        'bounded; the constraints cannot all hold: the tick says obstacle', 'obstacle')
    try:
        Obstacle('nan', 'sphere', [np.nan, 0.0, 0.0], np.eye(3), radius=0.01)
        message, ok = 'accepted', False
    except ValueError as exc:
        message, ok = str(exc), True
    cases.append(Case('contact', 'NaN in an obstacle', 'refused at the door', ok,
                      float('nan'), message, {}))
    return cases


EQUILIBRIUM_MATCH = 5e-4
"""Distance [m] within which a tick's effectors must match the equilibrium of its command."""


def _tendon_robot(seed):
    """
    Return the scene dict of a random beam-and-tendon robot of a fixed seed.

    The parts of docs/own-robot.md: 1-3 sections of 2-6 vertebra intervals (0.06-0.25 m in
    all), 3-9 tendons at random angles and radii (8-16 mm) ending at a section's last vertebra,
    2-20 N each, gravity or none. The backbone (R 6 mm) is as stiff as it takes for the tendons
    at full tension to bend it by 0.5-3 rad toward the side where they bend it most, for its own
    weight to droop it by at most 15 % of its length and for the tendons to strain it by at most
    8 % (linear estimates), as the property test's robots (test/core/random_robots.py).
    """
    rng = np.random.default_rng(seed)
    ends = [int(end) for end in np.cumsum(rng.integers(2, 7, size=int(rng.integers(1, 4))))]
    interval = float(rng.uniform(0.06, 0.25)) / ends[-1]
    tendons = [{'name': f'tendon_{i}', 'angle_deg': round(float(rng.uniform(0.0, 360.0)), 3),
                'radius': round(float(rng.uniform(0.008, 0.016)), 5),
                'end_vertebra': ends[int(rng.integers(len(ends)))],
                'max_tension': round(float(rng.uniform(2.0, 20.0)), 3)}
               for i in range(int(rng.integers(3, 10)))]
    gravity = bool(rng.random() < 0.7)
    directions = np.deg2rad(np.arange(0.0, 360.0, 5.0))
    # the tendons' bending moment times length, toward the side where it is largest [N m^2]
    bending = sum(t['max_tension'] * t['radius'] * interval * t['end_vertebra']
                  * np.maximum(np.cos(np.deg2rad(t['angle_deg']) - directions), 0.0)
                  for t in tendons)
    moment = float(bending.max())
    radius, density = 0.006, 1100.0
    second_moment, area = np.pi * radius ** 4 / 4.0, np.pi * radius ** 2
    youngs_modulus = max(moment / float(rng.uniform(0.5, 3.0)) / second_moment,
                         9.81 * density * area * (interval * ends[-1]) ** 3
                         / (8.0 * 0.15 * second_moment),
                         sum(t['max_tension'] for t in tendons) / (0.08 * area))
    return _beam_robot(f'random seed {seed}', ends[-1], interval, youngs_modulus,
                       tendons, gravity)


def _beam_robot(name, n_vertebrae, interval, youngs_modulus, tendons, gravity=True):
    """Return the scene dict of a solid 6 mm beam backbone with tendons and a tip effector."""
    return {'name': name, 'gravity': [0.0, 0.0, -9.81 if gravity else 0.0],
            'chain': {'type': 'beam_vertebrae', 'n_vertebrae': n_vertebrae,
                      'beams_per_interval': 1, 'interval_length': round(interval, 6),
                      'vertebra_mass': 0.0,
                      'backbone': {'youngs_modulus': float(f'{youngs_modulus:.4g}'),
                                   'poisson_ratio': 0.45, 'outer_radius': 0.006,
                                   'inner_radius': 0.0, 'density': 1100.0}},
            'cables': tendons,
            'effectors': [{'name': 'tip', 'frame': 'tip', 'offset': [0.0, 0.0, 0.0]}],
            'workspace_center': {'actuation_fraction': 0.3}}


def _staggered_robot(stagger):
    """
    Return the three-section robot that limit-cycled off its equilibrium before the gap check.

    3 x 4 intervals of 20 mm (0.24 m, the guide's rod as beams: E 20 MPa, R 6 mm), nine
    tendons, three per section at 120 deg, each section's set turned by ``stagger`` degrees,
    radius 12 mm, ending at vertebrae 4, 8 and 12, 0..10 N.
    """
    tendons = [{'name': f'section_{s}_{j}', 'angle_deg': 120.0 * j + stagger * s,
                'radius': 0.012, 'end_vertebra': 4 * (s + 1), 'max_tension': 10.0}
               for s in range(3) for j in range(3)]
    return _beam_robot(f'staggered {stagger:g} deg', 12, 0.02, 2.0e7, tendons)


def _robot_targets(scene, rng, n_inside):
    """Return ``[(kind, targets)]``: forward solves at random tensions, and each moved 20-60 mm."""
    targets = []
    for _ in range(n_inside):
        actuation = scene.lower_bounds + rng.random(scene.lower_bounds.size) * (
            scene.upper_bounds - scene.lower_bounds) * (rng.random(scene.lower_bounds.size) > 0.3)
        result = scene.forward(actuation, check_warnings=False)
        if not result.converged:
            continue
        direction = rng.standard_normal(3)
        targets += [('inside', result.effector_positions),
                    ('outside', result.effector_positions
                     + rng.uniform(0.02, 0.06) * direction / np.linalg.norm(direction))]
    return targets


def _equilibrium_contract(scene, targets, ticks):
    """
    Run ``ticks`` ticks (``step`` + ``prepare``) per target; return the contract's findings.

    The contract of a tick: its command is finite and within the bounds; its effectors match the
    equilibrium of its command (the forward solve warm-started from the solver's state) within
    :data:`EQUILIBRIUM_MATCH`, or it or the next tick is ``'not_converged'``; ``'solved'``,
    ``'saturated'`` and ``'unreachable'`` come with an ``equilibrium_gap`` within the
    tolerance; after an inside target's ticks the effectors are within 1 mm of it or the
    status is ``'unreachable'`` or ``'not_converged'``. Returns ``(violations, worst, counts)``:
    the violations in words, the largest distance from equilibrium of a tick not flagged
    ``'not_converged'`` [m] and counts of ticks, statuses and skipped forward solves.
    """
    solver = scene.make_inverse_solver()
    tolerance = solver.options.equilibrium_tolerance
    plan = [(kind, target) for kind, target in targets for _ in range(ticks)]
    violations, worst, counts, ticks_done = [], 0.0, {'ticks': 0, 'skipped': 0}, []
    for index, (kind, target) in enumerate(plan + plan[-1:]):
        out = solver.step(target)
        state = solver.state
        solver.prepare()
        if index == len(plan):
            ticks_done.append((out, math.nan))
            break
        counts['ticks'] += 1
        counts[out.status] = counts.get(out.status, 0) + 1
        where = f'target {index // ticks} ({kind}), tick {index % ticks}'
        if not _bounded(solver, out):
            violations.append(f'{where}: command outside the bounds')
        if out.status in ('solved', 'saturated', 'unreachable') and not (
                out.equilibrium_gap <= tolerance):
            violations.append(f'{where}: {out.status} with equilibrium gap '
                              f'{out.equilibrium_gap * 1e3:.3f} mm')
        off, _ = equilibrium_offset(scene, out, state)
        if math.isnan(off):
            counts['skipped'] += 1
        ticks_done.append((out, off))
        if kind == 'inside' and index % ticks == ticks - 1:
            left = float(np.linalg.norm(out.effector_positions - target, axis=1).max())
            if left > 1e-3 and out.status not in ('unreachable', 'not_converged'):
                violations.append(f'{where}: {out.status} {left * 1e3:.2f} mm from the target')
    for index, ((out, off), (after, _)) in enumerate(zip(ticks_done, ticks_done[1:])):
        if 'not_converged' in (out.status, after.status) or not off >= 0.0:
            continue
        worst = max(worst, off)
        if off > EQUILIBRIUM_MATCH:
            violations.append(f'target {index // ticks}, tick {index % ticks}: {out.status} '
                              f'{off * 1e3:.2f} mm off the equilibrium of its command '
                              f'(equilibrium gap {out.equilibrium_gap * 1e3:.3f} mm)')
    return violations, worst, counts


def random_robot_cases(tmp_dir, quick):
    """
    Random tendon robots (fixed seeds) and the staggered three-section robot: the contract.

    Each robot tracks targets inside its reach (forward solves at random tensions) and outside
    it (moved 20-60 mm), the staggered robot its target 40 mm from the workspace centre toward
    (0, -1, -1); every tick must keep the equilibrium contract of
    :func:`_equilibrium_contract` (the property test test/core/test_random_robots.py draws
    more robots, condensed chains and a closed loop).
    """
    ticks = 60 if quick else 120
    robots = [(_staggered_robot(stagger), None) for stagger in (0.0, 40.0, 60.0)]
    robots += [(_tendon_robot(seed), seed) for seed in range(1, 7 if quick else 25)]
    cases = []
    for spec, seed in robots:
        path = Path(tmp_dir) / 'random_robot.yaml'
        path.write_text(yaml.safe_dump(spec), encoding='utf-8')
        scene = load_scene(path)
        if seed is None:
            targets = [('given', scene.workspace_center + 0.04 * np.array([0.0, -1.0, -1.0])
                        / np.sqrt(2.0))]
            n_ticks = 2 * ticks
        else:
            targets, n_ticks = _robot_targets(scene, np.random.default_rng(seed), 2), ticks
        violations, worst, counts = _equilibrium_contract(scene, targets, n_ticks)
        statuses = ', '.join(f'{counts[s]} {s}' for s in sorted(counts)
                             if s not in ('ticks', 'skipped'))
        message = (f'{len(targets)} targets, {counts["ticks"]} ticks ({statuses}); '
                   f'{counts["skipped"]} forward solves did not converge')
        if violations:
            message = f'{len(violations)} violations, first: {violations[0]}; ' + message
        cases.append(Case('random robots', spec['name'],
                          'bounded; every tick at the equilibrium of its command (0.5 mm) or '
                          'not_converged (it or the next); solved/saturated/unreachable within '
                          'the equilibrium tolerance; inside targets reached (1 mm) or '
                          'unreachable/not_converged', not violations, worst, message,
                          {'ticks': counts['ticks'], 'violations': len(violations),
                           'tendons': len(spec['cables']),
                           'vertebrae': spec['chain']['n_vertebrae']}))
    return cases


def run_cases(quick, tmp_dir):
    """Run every case group; return the list of cases."""
    cases = []
    for group in (stiffness_cases, poisson_cases, length_cases, frame_count_cases,
                  rollup_cases, load_cases, buckling_cases):
        cases += group(quick)
    cases += actuator_cases(tmp_dir)
    cases += target_cases()
    cases += contact_cases()
    cases += random_robot_cases(tmp_dir, quick)
    return cases


def _figure(cases, path):
    """Plot the error of the stiffness-ratio and Poisson-ratio cases, and the frame timings."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    for kind in ('one link', 'half chain', 'tip link'):
        rows = [c for c in cases if c.group == 'stiffness ratio' and c.values['kind'] == kind]
        axes[0].semilogy([c.values['exponent'] for c in rows],
                         [max(c.error, 1e-17) for c in rows], 'o-', label=f'{kind}: tip error')
        axes[0].semilogy([c.values['exponent'] for c in rows],
                         [max(c.values['residual_over_load'], 1e-17) for c in rows], 'x:',
                         label=f'{kind}: residual / load')
    axes[0].axhline(1e-4, color='k', lw=0.8, ls='--')
    axes[0].set_xlabel('log10 stiffness factor of the stiff link(s)')
    axes[0].set_title('10 links, tip force: vs linear chain flexibility')
    axes[0].legend(fontsize=7)
    for order, style in ((1, 'o-'), (2, 's-')):
        rows = [c for c in cases if c.group == 'Poisson ratio' and c.values['order'] == order]
        x = [0.5 - c.values['nu'] for c in rows]
        axes[1].loglog(x, [c.values['torsion_ratio'] for c in rows], style,
                       label=f'P{order} torsion')
        axes[1].loglog(x, [c.values['bending_ratio'] for c in rows], style, mfc='none',
                       label=f'P{order} bending')
    axes[1].invert_xaxis()
    axes[1].set_xlabel('0.5 - nu')
    axes[1].set_ylabel('C_fe / C_timoshenko')
    axes[1].set_title('cylinder L = 40 mm, R = 10 mm: locking')
    axes[1].legend(fontsize=7)
    rows = [c for c in cases if c.group == 'frames']
    axes[2].loglog([c.values['frames'] for c in rows], [c.values['time_s'] for c in rows], 'o-',
                   label='solve time [s]')
    axes[2].loglog([c.values['frames'] for c in rows],
                   [c.values['peak_memory_mb'] for c in rows], 's-', label='peak memory [MB]')
    axes[2].set_xlabel('frames')
    axes[2].set_title('static solve, 1 mm tip deflection')
    axes[2].legend(fontsize=7)
    fig.suptitle(f'cbha_report stability — references: linear flexibility, Timoshenko; '
                 f'{platform.node()} ({platform.processor() or platform.machine()})', fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_report(cases, out_dir, elapsed, quick):
    """Write stability.md, stability.json and stability.png to ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    _figure(cases, out_dir / 'stability.png')
    lines = ['# Numerical stability on stiff and extreme cases', '',
             f'{"quick" if quick else "full"} run, {elapsed:.1f} s on {platform.node()}; '
             f'{sum(c.passed for c in cases)} of {len(cases)} cases pass.', '',
             '![stability](stability.png)', '',
             '| group | case | checked | error | pass | message to the user |',
             '|---|---|---|---|---|---|']
    for c in cases:
        lines.append(f'| {c.group} | {c.name} | {c.checked} | {c.error:.3g} | '
                     f'{"pass" if c.passed else "FAIL"} | {c.message.replace("|", "/")} |')
    (out_dir / 'stability.md').write_text('\n'.join(lines) + '\n', encoding='utf-8')
    (out_dir / 'stability.json').write_text(json.dumps(
        {'quick': quick, 'elapsed_s': elapsed, 'machine': platform.node(),
         'cases': [asdict(c) for c in cases]}, indent=1, default=float), encoding='utf-8')


def main(argv=None):
    """
    Run the stability report.

    Parameters
    ----------
    argv : list of str, optional
        ``[--quick] [--output DIR]``.

    Returns
    -------
    int
        0 when every case passes, 1 otherwise.

    """
    parser = argparse.ArgumentParser(prog='cbha_report stability',
                                     description=__doc__.strip().splitlines()[0])
    parser.add_argument('--quick', action='store_true', help='fewer, smaller cases (test suite)')
    parser.add_argument('--output', default='output/report', help='output directory')
    args = parser.parse_args(argv)
    import tempfile
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp_dir:
        cases = run_cases(args.quick, tmp_dir)
    elapsed = time.perf_counter() - started
    write_report(cases, Path(args.output), elapsed, args.quick)
    for c in cases:
        print(f'{"pass" if c.passed else "FAIL"}  {c.group:16s} {c.name:34s} err {c.error:9.3g}  '
              f'{c.message[:90]}')
    print(f'{sum(c.passed for c in cases)}/{len(cases)} cases pass, {elapsed:.1f} s; '
          f'written to {args.output}/stability.md')
    return 0 if all(c.passed for c in cases) else 1


if __name__ == '__main__':
    sys.exit(main())
