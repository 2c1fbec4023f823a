"""
Cases whose results are kept as reference arrays (``test/data/reference_results.npz``).

Each case runs one public entry of the core on a fixed input and returns its results as a dict
of arrays: the control tick on every shipped scene and on the scenes of the general actuator
paths (two cable groups, skinned-mesh cavities), with the options that take its other branches;
the static solve (the scenes' forward model); the shape estimator's updates; one identification.
``test/record_reference_results.py`` writes their results; ``test/core/test_reference_results.py``
compares the current code's against them. The arrays were recorded before the compiled kernels
were reorganised by equation (commit 72c4a64), so that the reorganisation is checked against
the code it replaced, not against itself.
"""

import math
from pathlib import Path

from cbha_inverse.core.actuation.actuators import ActuatorSet
from cbha_inverse.core.actuation.cables import CableGroup
from cbha_inverse.core.inverse.results import InverseOptions
from cbha_inverse.core.inverse.solver import InverseSolver
from cbha_inverse.estimate.shape import ShapeEstimator
from cbha_inverse.identify.fit import identify, parameter_names, TipPredictor
from cbha_inverse.scene import load_scene, resolve_scene_path
from cbha_inverse.scene.calibration import Calibration
import numpy as np
import yaml

REFERENCE = Path(__file__).resolve().parent / 'data' / 'reference_results.npz'
"""The recorded arrays, ``<case>/<name>`` keys."""

TICKS = 40
"""Control ticks per tick case."""

UNCHECKED = {'equilibrium_tolerance': math.inf, 'unreachable_distance': math.inf,
             'max_step': 1.0}
"""The paper's tick: no equilibrium check (no trust region, no restoration), no step limit and
no ``'unreachable'`` status, as the recorded ticks were made."""

TICK_OPTIONS = {
    'default': UNCHECKED,
    'every5': {'relinearize_every': 5, 'rate_limit': None, **UNCHECKED},
    'proxsuite': {'qp_solver': 'proxsuite', **UNCHECKED},
    'newton2': {'newton_steps': 2, **UNCHECKED},
}
"""Solver options of the tick cases (the one compiled call, the linear ticks between
linearisations, the QP in Python, the full Newton steps at fixed actuation)."""

TICK_SCENES = ('cbha', 'tendon_6f_8c', 'tendon_10f_16c')


def circle_targets(center, radius, n_ticks):
    """Return targets on a circle in the y-z plane around the last effector's centre."""
    phase = 2.0 * np.pi * np.arange(n_ticks) / 25.0
    targets = np.repeat(np.asarray(center, dtype=float)[None], n_ticks, axis=0)
    targets[:, -1, 1] += radius * np.cos(phase)
    targets[:, -1, 2] += radius * np.sin(phase)
    # one far target: the saturated branch
    targets[n_ticks // 2, -1] += [0.0, 0.5, -0.5]
    return targets


def run_ticks(solver, center, radius):
    """Return the results of :data:`TICKS` ticks of a solver on :func:`circle_targets`."""
    actuation, positions, residuals, statuses = [], [], [], []
    for target in circle_targets(center, radius, TICKS):
        result = solver.step(target)
        actuation.append(result.actuation)
        positions.append(result.effector_positions)
        residuals.append(result.residual_norm)
        statuses.append(result.status)
    state = solver.state
    return {'actuation': np.array(actuation), 'effector_positions': np.array(positions),
            'residual_norm': np.array(residuals), 'status': np.array(statuses),
            'positions': state.positions, 'rotations': state.rotations}


def _radius(name):
    return 0.04 if name.startswith('cbha') else 0.01


def mesh_cavity_scene(folder):
    """Return the CBHA scene with its cavities as skinned meshes (``cavity_model: mesh``)."""
    source = resolve_scene_path('cbha')
    data = yaml.safe_load(source.read_text())
    for section in data['chain']['sections']:
        section['segment'] = str((source.parent / section['segment']).resolve())
    data['cavity_model'] = 'mesh'
    data.pop('sensors', None)
    path = Path(folder) / 'cbha_mesh.yaml'
    path.write_text(yaml.safe_dump(data))
    return load_scene(path)


def two_cable_groups_solver(scene):
    """Return an inverse solver of a tendon scene whose cables form two groups."""
    cables = scene.actuators.groups[0].cables
    half = len(cables) // 2
    n_frames = scene.model.n_frames
    actuators = ActuatorSet([CableGroup(cables[:half], n_frames),
                             CableGroup(cables[half:], n_frames)], n_frames)
    return InverseSolver(scene.model, actuators, scene.effectors, gravity=scene.gravity,
                         options=InverseOptions(**UNCHECKED))


def tick_cases(folder):
    """Yield ``(case name, results)`` of every tick case."""
    for name in TICK_SCENES:
        scene = load_scene(name)
        for option, values in TICK_OPTIONS.items():
            solver = scene.make_inverse_solver(**values)
            yield f'tick_{name}_{option}', run_ticks(solver, scene.workspace_center,
                                                     _radius(name))
    scene = load_scene('tendon_6f_8c')
    yield 'tick_two_cable_groups', run_ticks(two_cable_groups_solver(scene),
                                             scene.workspace_center, 0.01)
    scene = mesh_cavity_scene(folder)
    yield 'tick_cbha_mesh', run_ticks(scene.make_inverse_solver(**UNCHECKED),
                                      scene.workspace_center, 0.04)


def static_cases():
    """Yield ``(case name, results)`` of forward solves at a few actuations of every scene."""
    rng = np.random.default_rng(7)
    for name in TICK_SCENES:
        scene = load_scene(name)
        positions, quaternions, iterations, residuals = [], [], [], []
        for fraction in rng.uniform(0.0, 1.0, (3, len(scene.actuator_names))):
            actuation = scene.lower_bounds + fraction * (scene.upper_bounds - scene.lower_bounds)
            result = scene.forward(actuation)
            positions.append(result.positions)
            quaternions.append(result.quaternions)
            iterations.append(result.iterations)
            residuals.append(result.residual_norm)
        yield f'static_{name}', {'positions': np.array(positions),
                                 'quaternions': np.array(quaternions),
                                 'iterations': np.array(iterations),
                                 'residual_norm': np.array(residuals)}


ESTIMATOR_PRESSURES = np.array([[1.2e5, 0.3e5, 0.0, 0.2e5, 0.9e5, 0.0],
                                [0.4e5, 1.0e5, 0.2e5, 0.6e5, 0.0, 0.7e5]])


def estimator_case():
    """Return the shape estimator's updates on a plant with gain and stiffness errors."""
    scene = load_scene('cbha')
    plant = load_scene('cbha', calibration=Calibration(
        section_stiffness={'inner': 1.15, 'outer': 0.85},
        actuator_gain={'inner_over': 1.1, 'outer_left': 0.95}))
    estimator = ShapeEstimator.from_scene(scene)
    tips, z = [], []
    for pressures in ESTIMATOR_PRESSURES:
        state = plant.forward(pressures, strict=True).state
        readings = plant.sensors.readings(plant.sensors.lengths(state.positions,
                                                                state.rotations))
        for _ in range(6):
            estimate = estimator.update(readings, pressures)
            tips.append(estimate.tip)
            z.append(estimator._data.z.copy())
    return {'tip': np.array(tips), 'z': np.array(z),
            'covariance': estimator._data.covariance.copy()}


IDENTIFY_TRUTH = np.array([0.85, 1.1, 0.9, 1.05, 1.1, 0.95, 1.08, 0.92])


def identification_case():
    """Return one identification of the CBHA from noisy tips of a plant with known errors."""
    rng = np.random.default_rng(3)
    pressures = rng.uniform(0.0, 150e3, (12, 6))
    names = parameter_names(load_scene('cbha'))
    tips = TipPredictor('cbha', names, pressures)(IDENTIFY_TRUTH)
    tips = tips + rng.normal(0.0, 2e-4, tips.shape)
    result = identify('cbha', pressures, tips, max_relative_error=1.0, max_correlation=1.0)
    return {'values': result.values, 'standard_errors': result.standard_errors,
            'rms_after': np.array(result.rms_after)}


def all_cases(folder):
    """Yield ``(case name, results)`` of every case (``folder``: for generated scene files)."""
    yield from tick_cases(folder)
    yield from static_cases()
    yield 'estimator', estimator_case()
    yield 'identification', identification_case()
