"""
The inverse solver's equilibrium contract on random robots (hypothesis, derandomised, bounded).

Random valid robots (:mod:`test.core.random_robots`: beam and condensed chains, 1-4 sections,
3-12 tendons, with and without gravity) track targets inside their reach (forward solves at random
admissible tensions) and outside it (an inside target moved by 20-60 mm), one
``step`` + ``prepare`` per tick. Every tick must keep the contract:

- the command is finite and within the bounds;
- the tick's model state is at equilibrium: the forward solve of its actuation, warm-started
  from the solver's state, puts the effectors within :data:`EQUILIBRIUM_MATCH` of the tick's
  ``effector_positions``, or the tick (or, flagged one tick late, the next) is
  ``'not_converged'``; a forward solve that does not converge skips the tick (counted);
- ``'solved'``, ``'saturated'`` and ``'unreachable'`` come with an ``equilibrium_gap`` within
  ``equilibrium_tolerance``; ``'unreachable'`` has an actuator at a bound and a predicted gap
  above ``unreachable_distance``;
- after the ticks on an inside target the model's effectors are within :data:`REACHED` of it, or
  the status is ``'unreachable'`` or ``'not_converged'``, or the tick is ``'solved'`` and the
  effectors still approach it (:data:`PROGRESS` closer than :data:`PROGRESS_TICKS` ticks before);
- a closed loop (``TargetCorrector``) on a 10 % softer plant, its solver's step limited to
  :data:`LOOP_MAX_STEP` of each range, its target moving along ramps through the same targets,
  never moves the plant's effectors by more per tick than the target moves plus
  :data:`LOOP_STEP_BOUND`.

The test collects every violation of every robot and fails once at the end with all of them and
the coverage (robots, targets, ticks) in its message (``pytest -s`` prints the coverage too).
Robots that once violated the contract are kept as explicit regression cases
(:data:`REGRESSIONS`, with the three-section staggered robot of :func:`staggered_robot`).
"""

from collections import Counter
import json
import math
import time

from cbha_inverse.core.inverse.correction import TargetCorrector
from cbha_inverse.core.inverse.results import HELD_STATUSES
from cbha_inverse.report.stability import equilibrium_offset
from hypothesis import assume, given, HealthCheck, settings, strategies as st
import numpy as np
import pytest
from random_robots import (condense_rod, load_robot, robot_specs, staggered_robot,
                           staggered_target, STAGGERS)

EQUILIBRIUM_MATCH = 5e-4
"""The contract's distance [m] between a tick's effectors and the model's equilibrium."""
REACHED = 1e-3
"""Distance [m] of the model's effectors from an inside target after the ticks."""
PROGRESS = 0.1
"""A target not yet reached must be this fraction closer than :data:`PROGRESS_TICKS` before."""
PROGRESS_TICKS = 20
"""Ticks over which an unreached target's approach is measured."""
TICKS = 120
"""Ticks per target (``step`` + ``prepare``)."""
LOOP_SPEED = 2e-3
"""Largest move [m] of the closed loop's target per tick along its ramps."""
LOOP_MAX_STEP = 0.1
"""The closed loop's largest actuator change per tick, a fraction of its range."""
LOOP_HOLD = 30
"""Ticks the closed loop's target holds at each waypoint."""
LOOP_STEP_BOUND = 5e-3
"""
Largest move [m] of a plant effector per closed-loop tick beyond the target's own move.

Where it comes from: the model reaches a reachable corrected target within a tick, so its
effectors move by about the corrected target's move; the plant, 10 % softer, moves ~11 % more
than the model (0.2 mm on a 2 mm ramp step); the corrector's integral moves the corrected target
by ``gain`` times the measured error per tick, at most 3 mm for errors up to 30 mm (the
correction's cap; the plant's extra compliance leaves errors of a few mm on these robots); the
rest (about 2 mm) is margin for the linearisation. A tick beyond it is a jump or an oscillation
of the loop. A tick whose plant solve does not converge keeps the last measurement, and the next
comparison allows the bound once per tick since.
"""
EXAMPLES = 25
"""Random robots per run (derandomised: the same robots every run)."""


class Tally:
    """Coverage and violations of a run, with a summary for the failure message."""

    def __init__(self):
        """Start empty."""
        self.counts = Counter()
        self.statuses = Counter()
        self.violations = []
        self.reproducers = []       # the scene dict and targets of each robot with a violation
        self.started = time.perf_counter()

    def violation(self, label, text):
        """Record a violation of robot ``label``."""
        self.violations.append(f'{label}: {text}')

    def summary(self):
        """Return the coverage and the violations in words."""
        c = self.counts
        lines = [f'{c["robots"]} robots ({c["beam"]} beam, {c["segments"]} condensed, '
                 f'{c["gravity"]} with gravity, {c["rejected"]} rejected as unable to hold '
                 f'their weight), {c["targets"]} targets ({c["inside"]} inside, '
                 f'{c["outside"]} outside, {c["target_skipped"]} inside targets skipped: their '
                 f'forward solve failed), {c["ticks"]} contract ticks, {c["loop_ticks"]} '
                 f'closed-loop ticks; {c["forward_skipped"]} ticks skipped (forward solve did '
                 f'not converge), {c["plant_skipped"]} closed-loop ticks without a plant '
                 f'equilibrium, next-tick not_converged rule needed {c["next_tick"]} times; '
                 f'statuses {dict(self.statuses)}; {len(self.violations)} violations; '
                 f'{time.perf_counter() - self.started:.1f} s']
        lines += self.violations[:40]
        if len(self.violations) > 40:
            lines.append(f'... and {len(self.violations) - 40} more')
        return '\n'.join(lines + self.reproducers)


def admissible_actuation(scene, rng):
    """Return random tensions within the bounds (each tendon slack with probability 1/3)."""
    lower, upper = scene.lower_bounds, scene.upper_bounds
    active = rng.random(lower.size) > 1.0 / 3.0
    return np.where(active, lower + rng.random(lower.size) * (upper - lower), lower)


def sample_targets(scene, rng, tally, n_inside=4):
    """
    Return ``[(kind, targets (k, 3))]``: inside targets, each followed by one outside it.

    Inside: the effectors of a forward solve at a random admissible actuation (a solve that does
    not converge is skipped and counted). Outside: that target moved 20-60 mm in a random
    direction.
    """
    targets = []
    for _ in range(n_inside):
        result = scene.forward(admissible_actuation(scene, rng), check_warnings=False)
        if not result.converged:
            tally.counts['target_skipped'] += 1
            continue
        inside = result.effector_positions.copy()
        direction = rng.standard_normal(3)
        direction /= np.linalg.norm(direction)
        outside = inside + rng.uniform(0.02, 0.06) * direction
        targets += [('inside', inside), ('outside', outside)]
    return targets


def _bounded(solver, actuation):
    """Whether a command is finite and within the solver's bounds."""
    return bool(np.all(np.isfinite(actuation)) and np.all(actuation >= solver.lower_bounds)
                and np.all(actuation <= solver.upper_bounds))


def check_contract(scene, targets, tally, label, ticks=TICKS):
    """
    Track each target for ``ticks`` ticks (``step`` + ``prepare``); record contract violations.

    One solver runs through every target in turn. A tick's model state is checked against the
    forward solve of its actuation warm-started from the solver's state right after the tick.
    An inside target is reached (within :data:`REACHED`), or the last tick says why not
    (``'unreachable'``, ``'not_converged'``), or the trust region still carries the tip toward
    it: its distance shrank by :data:`PROGRESS` over the last :data:`PROGRESS_TICKS` ticks.
    """
    solver = scene.make_inverse_solver()
    options = solver.options
    plan = [(kind, target) for kind, target in targets for _ in range(ticks)]
    plan.append(plan[-1])      # one more tick: the status of the tick after the last
    records, distances = [], []
    for index, (kind, target) in enumerate(plan):
        out = solver.step(target)
        state = solver.state
        solver.prepare()
        if index == len(plan) - 1:
            records.append((out, None))
            break
        tally.statuses[out.status] += 1
        tally.counts['ticks'] += 1
        where = f'{kind} target {index // ticks}, tick {index % ticks}'
        if not _bounded(solver, out.actuation):
            tally.violation(label, f'{where}: command {out.actuation} outside the bounds')
        off, forward = equilibrium_offset(scene, out, state)
        if math.isnan(off):
            tally.counts['forward_skipped'] += 1
        records.append((out, (where, off, forward)))
        if out.status in ('solved', 'saturated', 'unreachable') and not (
                out.equilibrium_gap <= options.equilibrium_tolerance):
            tally.violation(label, f'{where}: status {out.status} with equilibrium_gap '
                            f'{out.equilibrium_gap * 1e3:.3f} mm')
        if out.status == 'unreachable':
            margin = 1e-9 * (solver.upper_bounds - solver.lower_bounds)
            at_bound = np.any(out.saturated & ((out.actuation <= solver.lower_bounds + margin)
                                               | (out.actuation >= solver.upper_bounds - margin)))
            if not (at_bound and out.predicted_error > options.unreachable_distance):
                tally.violation(label, f'{where}: unreachable without an actuator held at a '
                                f'bound and a predicted gap above unreachable_distance '
                                f'(predicted {out.predicted_error * 1e3:.3f} mm)')
        distances.append(float(np.linalg.norm(out.effector_positions - target, axis=1).max()))
        if (index + 1) % ticks == 0 and kind == 'inside':
            reached = distances[-1]
            earlier = distances[-PROGRESS_TICKS - 1]
            approaching = out.status == 'solved' and reached < (1.0 - PROGRESS) * earlier
            if reached > REACHED and not approaching and out.status not in (
                    'unreachable', 'not_converged'):
                tally.violation(label, f'{where}: inside target left {reached * 1e3:.2f} mm '
                                f'away with status {out.status} (predicted '
                                f'{out.predicted_error * 1e3:.2f} mm)')
    for (out, checked), (after, _) in zip(records, records[1:]):
        where, off, forward = checked
        if not off > EQUILIBRIUM_MATCH:
            continue
        if out.status == 'not_converged':
            continue
        if after.status == 'not_converged':
            tally.counts['next_tick'] += 1
            continue
        tally.violation(label, f'{where}: status {out.status} (next {after.status}) but the '
                        f'effectors are {off * 1e3:.2f} mm off the equilibrium of the command '
                        f'(equilibrium_gap {out.equilibrium_gap * 1e3:.3f} mm, forward load '
                        f'steps {forward.load_steps})')


def ramp(waypoints, start, speed=LOOP_SPEED, hold=LOOP_HOLD):
    """Return the targets (k, 3) of each tick: ramps at ``speed`` per tick, holds at waypoints."""
    path, here = [], start
    for waypoint in waypoints:
        steps = max(1, math.ceil(np.linalg.norm(waypoint - here, axis=1).max() / speed))
        path += [here + (waypoint - here) * (i + 1) / steps for i in range(steps)]
        path += [waypoint] * hold
        here = waypoint
    return path


def check_closed_loop(scene, plant, targets, tally, label):
    """
    Run the closed loop on the softer plant along ramps through the targets; record jumps.

    The plant starts at rest, the target at the model's rest effectors; each tick corrects the
    target with the last measurement, steps the solver and solves the plant at the command.
    The solver limits each actuator's step to :data:`LOOP_MAX_STEP` of its range (the
    ``max_step`` a robot is run with when the arm must not jump); without it one tick may move
    an actuator across its whole range, which the bound per tick does not allow.
    """
    solver = scene.make_inverse_solver(max_step=LOOP_MAX_STEP)
    k = len(scene.effector_names)
    corrector = TargetCorrector(k, gain=0.1, max_correction=0.03)
    path = ramp([target for _, target in targets], scene.rest_effector_positions)
    result = plant.forward(solver.actuation.copy(), check_warnings=False)
    plant_state, measured = result.state, result.effector_positions
    out, goal, previous_target, elapsed = None, None, scene.rest_effector_positions, 0
    for index, target in enumerate(path):
        saturated = out is not None and out.status in HELD_STATUSES
        predicted_gap = None if out is None else goal - out.effector_positions
        goal = corrector.update(target, measured, saturated=saturated, predicted_gap=predicted_gap)
        out = solver.step(goal)
        solver.prepare()
        tally.counts['loop_ticks'] += 1
        if not _bounded(solver, out.actuation):
            tally.violation(label, f'closed loop tick {index}: command outside the bounds')
        result = plant.forward(out.actuation, initial_state=plant_state, check_warnings=False)
        elapsed += 1
        if not result.converged:
            # no equilibrium of the plant: the loop keeps its last measurement
            tally.counts['plant_skipped'] += 1
            continue
        moved = float(np.linalg.norm(result.effector_positions - measured, axis=1).max())
        allowed = float(np.linalg.norm(target - previous_target, axis=1).max()) + (
            elapsed * LOOP_STEP_BOUND)
        if moved > allowed:
            tally.violation(label, f'closed loop tick {index}: the plant moved {moved * 1e3:.2f} '
                            f'mm (allowed {allowed * 1e3:.2f} mm), status {out.status}')
        plant_state, measured, previous_target = result.state, result.effector_positions, target
        elapsed = 0


def count(tally, spec, targets):
    """Count a robot and its targets in the tally."""
    tally.counts['robots'] += 1
    tally.counts['segments' if spec['chain']['type'] == 'segments' else 'beam'] += 1
    tally.counts['gravity'] += bool(np.any(spec['gravity']))
    tally.counts['targets'] += len(targets)
    for kind, _ in targets:
        tally.counts[kind] += 1


def run_robot(spec, directory, rng, tally, label):
    """Load a robot and its 10 % softer plant; run the contract and the closed loop."""
    loaded = load_robot(spec, directory)
    if loaded is None:
        tally.counts['rejected'] += 1
        return False
    scene, path = loaded
    targets = sample_targets(scene, rng, tally)
    count(tally, spec, targets)
    if not targets:
        return True
    before = len(tally.violations)
    check_contract(scene, targets, tally, label)
    from cbha_inverse.scene import load_scene
    check_closed_loop(scene, load_scene(path, stiffness_scale=0.9), targets, tally, label)
    if len(tally.violations) > before:
        # full precision: a target rounded to 1 um can change the outcome
        listed = [[kind, target.tolist()] for kind, target in targets]
        tally.reproducers.append(f'{label}: robot {json.dumps(spec)}; targets '
                                 f'{json.dumps(listed)}')
    return True


@pytest.fixture(scope='session')
def rod_segment(tmp_path_factory):
    """Condense the guide's rod segment once per session (gmsh, ~0.3 s); return its path."""
    return condense_rod(tmp_path_factory.mktemp('rod_segment'))


def test_random_robots_keep_the_equilibrium_contract(rod_segment, tmp_path_factory):
    """Every tick of every random robot keeps the contract of the module docstring."""
    tally = Tally()

    @settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
    @given(spec=robot_specs(rod_segment), seed=st.integers(0, 2 ** 31 - 1))
    def explore(spec, seed):
        label = f'robot {tally.counts["robots"] + tally.counts["rejected"]} (seed {seed})'
        assume(run_robot(spec, tmp_path_factory.mktemp('robot'), np.random.default_rng(seed),
                         tally, label))

    explore()
    print('\n' + tally.summary())
    assert not tally.violations, tally.summary()


def beam_robot(n_vertebrae, interval, youngs_modulus, outer_radius, tendons, *, gravity=True,
               inner_radius=0.0, density=1100.0, vertebra_mass=0.0, beams_per_interval=1,
               tip_offset=0.0):
    """Return the scene dict of a beam robot; ``tendons``: (angle_deg, radius, end, max) rows."""
    return {'name': 'regression', 'gravity': [0.0, 0.0, -9.81 if gravity else 0.0],
            'workspace_center': {'actuation_fraction': 0.3},
            'chain': {'type': 'beam_vertebrae', 'n_vertebrae': n_vertebrae,
                      'beams_per_interval': beams_per_interval, 'interval_length': interval,
                      'vertebra_mass': vertebra_mass,
                      'backbone': {'youngs_modulus': youngs_modulus, 'poisson_ratio': 0.45,
                                   'outer_radius': outer_radius, 'inner_radius': inner_radius,
                                   'density': density}},
            'cables': [{'name': f'tendon_{i}', 'angle_deg': angle, 'radius': radius,
                        'end_vertebra': end, 'max_tension': most}
                       for i, (angle, radius, end, most) in enumerate(tendons)],
            'effectors': [{'name': 'tip', 'frame': 'tip', 'offset': [tip_offset, 0.0, 0.0]}]}


REGRESSIONS = [
    # 'solved' (and next tick 'solved') 0.80 mm off the equilibrium of its command, with
    # equilibrium_gap 0.185 mm: the first-order gap |J_e K^-1 r| underestimates the distance 4x
    # on the first tick of the inside target after 100 ticks on the outside one (a 2 N step;
    # minimised from random robot seed 131)
    pytest.param(beam_robot(12, 0.019118, 2.559e8, 0.00405, [
        (259.501, 0.0073, 12, 12.96), (25.683, 0.0154, 12, 3.753),
        (128.641, 0.00859, 12, 2.436), (229.167, 0.01388, 6, 17.01),
        (293.208, 0.01223, 12, 16.059), (287.337, 0.00701, 6, 13.049)],
        density=953.7, vertebra_mass=0.00378, tip_offset=0.0024),
        [('outside', [[0.243857, -0.013563, -0.072135]]),
         ('inside', [[0.218492, -0.016097, -0.069007]])], TICKS, id='first_order_gap_4x_short'),
    # after 4 targets the trust region sits near its floor (gap 50-100 um, just above the
    # growth threshold): 100 ticks of 'solved' move the tip only 94 of 114 mm toward an inside
    # target (a 0.16 m rod curled past 90 deg by 12 tendons; random robot seed 215 of the first
    # generator, 100 ticks per target); its closed loop jumps by up to 166 mm
    pytest.param(beam_robot(2, 0.078907, 1.502e7, 0.00688, [
        (188.496, 0.00678, 2, 10.192), (208.682, 0.01476, 2, 7.991),
        (115.953, 0.0083, 2, 5.935), (226.618, 0.01552, 2, 16.196),
        (354.378, 0.00611, 2, 17.03), (235.296, 0.01349, 2, 2.601),
        (193.321, 0.00697, 2, 8.093), (38.66, 0.0113, 2, 8.676), (199.033, 0.0084, 2, 18.144),
        (193.259, 0.01394, 2, 6.499), (65.488, 0.01376, 2, 5.635),
        (69.015, 0.01314, 2, 11.783)], gravity=False, density=1261.6, vertebra_mass=0.00312,
        beams_per_interval=2, tip_offset=0.02705),
        [('inside', [[-0.01899748456638911, -0.08539861969296494, -0.06018693195864367]]),
         ('outside', [[-0.04818519201931814, -0.06743328658815038, -0.06642030343727409]]),
         ('inside', [[0.17954640468044206, -0.006510648704025996, 0.022778761003888842]]),
         ('outside', [[0.19985957531583498, -0.012833760080867812, 0.011668692871854885]]),
         ('inside', [[-0.020939634087517506, -0.09867169137197773, -0.029625959209758693]]),
         ('outside', [[-0.04397191701438493, -0.10411143387673545, -0.04885199679772918]])],
        100, id='trust_region_stalls', marks=pytest.mark.xfail(strict=True, reason=(
            'open: the 10 % softer plant of this rod curled past 90 deg finds no equilibrium '
            'on 100-200 of its closed-loop ticks, and the loop jumps 7-22 mm'))),
    # closed loop, from rest: the ramp's second tick (target 4 mm from rest) co-contracts the
    # base and top tendons by 5 N in one tick; the linear model predicts 0.3 mm, the state lands
    # 7-9 mm away (not_converged) and the plant's tip jumps 9-14 mm (minimised from seed 6 of
    # the first generator; the same with condensed rod segments)
    pytest.param(beam_robot(10, 0.02, 2.0e7, 0.006, [
        (189.0, 0.012, 3, 8.0), (330.0, 0.013, 8, 13.0), (15.0, 0.007, 8, 10.0)],
        gravity=False), [('outside', [[0.166, 0.094, -0.030]])], TICKS, id='jump_from_rest'),
    # closed loop, leaving the reach: the first ramp step toward the outside target moves the
    # tendons by 6 N along the null space (the target moved 1.9 mm), the next tick's state is
    # 9 mm off equilibrium and the plant jumps 15 mm (seed 1552 of the first generator)
    pytest.param(beam_robot(15, 0.015691, 3.249e8, 0.00431, [
        (305.192, 0.0136, 3, 13.566), (0.03, 0.01514, 3, 10.297), (284.679, 0.00727, 3, 2.0),
        (281.923, 0.01494, 7, 2.0), (0.0, 0.011, 7, 6.978), (0.0, 0.01567, 15, 19.0)],
        inner_radius=0.00137, density=977.6, vertebra_mass=0.00134, beams_per_interval=2),
        [('inside', [[0.234046, 0.019937, -0.0115]]),
         ('outside', [[0.273318, 0.023328, -0.027678]]),
         ('inside', [[0.224161, 0.062448, -0.019805]]),
         ('outside', [[0.185589, 0.079244, -0.016457]])], TICKS, id='null_space_jump'),
]
"""Robots, targets and ticks per target that violated the contract once (minimised)."""


@pytest.mark.parametrize('spec, targets, ticks', REGRESSIONS)
def test_regression_robot_keeps_the_contract(tmp_path, spec, targets, ticks):
    """A robot that once violated the contract: the same checks on its recorded targets."""
    tally = Tally()
    scene, path = load_robot(spec, tmp_path)
    targets = [(kind, np.array(target, dtype=float)) for kind, target in targets]
    count(tally, spec, targets)
    check_contract(scene, targets, tally, 'regression', ticks=ticks)
    from cbha_inverse.scene import load_scene
    check_closed_loop(scene, load_scene(path, stiffness_scale=0.9), targets, tally,
                      'regression')
    print('\n' + tally.summary())
    assert not tally.violations, tally.summary()


@pytest.mark.parametrize('stagger', STAGGERS)
def test_staggered_three_section_robot_keeps_the_contract(rod_segment, tmp_path, stagger):
    """The robot that limit-cycled 25 mm off its equilibrium as 'saturated', 400 ticks."""
    tally = Tally()
    scene, path = load_robot(staggered_robot(rod_segment, stagger), tmp_path)
    target = staggered_target(scene)
    count(tally, staggered_robot(rod_segment, stagger), [('given', target)])
    check_contract(scene, [('given', target)], tally, f'staggered {stagger:g} deg', ticks=400)
    from cbha_inverse.scene import load_scene
    check_closed_loop(scene, load_scene(path, stiffness_scale=0.9), [('given', target)],
                      tally, f'staggered {stagger:g} deg')
    print('\n' + tally.summary())
    assert not tally.violations, tally.summary()
