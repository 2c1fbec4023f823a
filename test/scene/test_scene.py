"""Scenes: loading, forward/inverse consistency, bounds, redundancy, saturation, imports."""

import json
import subprocess
import sys

from cbha_inverse.core.inverse.solver import TargetCorrector
from cbha_inverse.paths import config_path
from cbha_inverse.scene import load_scene
import numpy as np
from oracles.actuation import oracle
import pytest

TENDON_SCENES = ['tendon_6f_8c', 'tendon_10f_16c']
ALL_SCENES = TENDON_SCENES + ['cbha']


def _load(name):
    return load_scene(config_path('scenes', f'{name}.yaml'))


@pytest.fixture(scope='module', params=ALL_SCENES)
def scene(request):
    return _load(request.param)


def test_scene_api(scene):
    m = len(scene.actuator_names)
    k = len(scene.effector_names)
    assert scene.lower_bounds.shape == scene.upper_bounds.shape == (m,)
    assert np.all(scene.upper_bounds > scene.lower_bounds)
    assert scene.rest_effector_positions.shape == (k, 3)
    solver = scene.make_inverse_solver()
    assert solver.actuator_names == scene.actuator_names
    assert solver.effector_names == scene.effector_names
    np.testing.assert_array_equal(solver.upper_bounds, scene.upper_bounds)
    assert scene.workspace_center.shape == (k, 3)


@pytest.mark.parametrize('relinearize_every', [1, 5])
def test_forward_inverse_consistency(scene, relinearize_every):
    """Random in-bounds actuation → forward p*; the inverse solver from rest reaches p*."""
    rng = np.random.default_rng(42)
    m = len(scene.actuator_names)
    span = scene.upper_bounds - scene.lower_bounds
    actuation = scene.lower_bounds + span * rng.uniform(0.0, 0.6, m)
    target = scene.forward(actuation, strict=True).effector_positions
    solver = scene.make_inverse_solver(relinearize_every=relinearize_every)
    errors, statuses = [], []
    for _ in range(30):
        out = solver.step(target)
        assert np.all(out.actuation >= solver.lower_bounds)
        assert np.all(out.actuation <= solver.upper_bounds)
        statuses.append(out.status)
        errors.append(np.abs(out.effector_positions - target).max())
    # from rest the first steps leave equilibrium, and say so; then the state converges
    assert set(statuses) <= {'solved', 'saturated', 'not_converged'}, statuses
    assert set(statuses[-10:]) <= {'solved', 'saturated'}, statuses
    # All 30 ticks: stopping at the first small *predicted* error can leave the solver's state
    # off equilibrium (residual ~1 N), so the forward check below would pass or fail by luck.
    reached = scene.forward(out.actuation, initial_state=solver.state, strict=True)
    assert np.linalg.norm(reached.effector_positions - target, axis=1).max() < 1e-4, errors
    assert set(out.timings) >= {'assembly', 'factor', 'projection', 'qp', 'total'}


def test_unreachable_target_saturates_finitely(scene):
    solver = scene.make_inverse_solver()
    far = scene.rest_effector_positions + [0.0, 5.0, -5.0]
    statuses = []
    for _ in range(30):
        out = solver.step(far)
        assert np.all(np.isfinite(out.actuation))
        assert np.all(np.isfinite(out.effector_positions))
        assert np.all(out.actuation >= solver.lower_bounds)
        assert np.all(out.actuation <= solver.upper_bounds)
        statuses.append(out.status)
        if out.status == 'unreachable':
            # the closest reachable point, a tenth of a metre and more from the target
            assert out.predicted_error > 0.1 and out.saturated.any()
    # at the reach's extreme the state may leave equilibrium now and then: it says so
    assert set(statuses) == {'unreachable', 'not_converged'}
    assert statuses[-20:].count('unreachable') >= 10, statuses


def test_bad_targets_are_rejected_or_refused():
    scene = _load('tendon_6f_8c')
    solver = scene.make_inverse_solver()
    out = solver.step([[np.nan, 0.0, 0.0]])
    assert out.status == 'rejected'
    np.testing.assert_array_equal(out.actuation, np.zeros(len(scene.actuator_names)))
    with pytest.raises(ValueError):
        solver.step(np.zeros((2, 3)))


def test_redundant_tendons_give_the_same_solution_run_to_run():
    scene = _load('tendon_10f_16c')
    targets = scene.rest_effector_positions + [[0.0, 0.004, 0.0], [0.0, 0.01, 0.008]]
    runs = []
    for _ in range(2):
        solver = scene.make_inverse_solver()
        runs.append(np.array([solver.step(targets).actuation for _ in range(8)]))
    # equal up to floating-point summation order (numpy/BLAS kernels depend on alignment): the
    # regularised QP has a unique solution, the 16 tendons do not drift between runs
    np.testing.assert_allclose(runs[0], runs[1], rtol=1e-6, atol=1e-9)


def test_gauss_seidel_option_reaches_the_same_point():
    scene = _load('tendon_6f_8c')
    target = scene.forward(np.array([3.0, 0, 0, 1.0, 0, 2.0, 0, 0])).effector_positions
    for qp_solver in ('proxsuite', 'gauss_seidel'):
        solver = scene.make_inverse_solver(qp_solver=qp_solver)
        for _ in range(30):
            out = solver.step(target)
        assert np.abs(out.effector_positions - target).max() < 1e-5


def test_inflating_one_cbha_tube_bends_away_from_it():
    scene = _load('cbha')
    from cbha_inverse.fem.segment_io import load_segment
    from cbha_inverse.scene.segments import cavity_surfaces
    surfaces = cavity_surfaces(load_segment(config_path('segments', 'cbha_segment.yaml')))
    rest = scene.forward(np.zeros(6), strict=True)
    axis = rest.positions[-1] - rest.positions[0]
    for k, name in enumerate(scene.actuator_names[:3]):
        pressure = np.zeros(6)
        pressure[k] = 0.5 * scene.upper_bounds[k]
        tip = scene.forward(pressure, strict=True).positions[-1]
        move = tip - rest.positions[-1]
        move -= axis * (move @ axis) / (axis @ axis)
        centroid = surfaces[name.split('_')[-1]][0].mean(axis=0)
        side = np.array([0.0, centroid[1], centroid[2]])
        side /= np.linalg.norm(side)
        assert move @ side < -0.5 * np.linalg.norm(move), name


def test_tendon_scene_imports_no_gmsh_meshio_or_cv2():
    code = ('import sys, json; from cbha_inverse.scene import load_scene; '
            "s = load_scene('tendon_6f_8c'); "
            's.make_inverse_solver().step(s.rest_effector_positions); '
            "names = ('gmsh', 'meshio', 'cv2', 'rclpy'); "
            'print(json.dumps([m for m in names if m in sys.modules]))')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         cwd=str(config_path().parents[0]), check=True, timeout=60)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []


def test_closed_loop_correction_removes_model_error():
    """The plant is 20 % stiffer than the model: integral action brings the tip to the target."""
    model = _load('tendon_6f_8c')
    plant = load_scene(config_path('scenes', 'tendon_6f_8c.yaml'), stiffness_scale=1.2)
    target = model.workspace_center + [[0.0, 0.008, -0.004]]
    solver = model.make_inverse_solver()
    corrector = TargetCorrector(1, gain=0.5, max_correction=0.02)
    measured, state, errors, saturated = None, None, [], False
    for _ in range(40):
        out = solver.step(corrector.update(target, measured, saturated))
        saturated = out.status == 'saturated'
        real = plant.forward(out.actuation, initial_state=state, strict=True)
        measured, state = real.effector_positions, real.state
        errors.append(np.linalg.norm(measured - target))
    assert errors[0] > 5e-4
    assert errors[-1] < 1e-5, errors


def test_forward_model_agrees_with_the_core_static_solver():
    """Small tensions (where the structural-tangent Newton of statics also converges)."""
    from cbha_inverse.core.statics import solve_static
    scene = _load('tendon_6f_8c')
    actuation = np.array([0.3, 0.0, 0.1, 0.0, 0.2, 0.0, 0.0, 0.1])
    ours = scene.forward(actuation, strict=True)

    def load(state):
        return oracle(scene.actuators).loads(state.positions, state.rotations, actuation)[1:]

    core = solve_static(scene.model, gravity=scene.gravity, load_function=load)
    assert core.converged, core.message
    np.testing.assert_allclose(ours.positions, core.positions, atol=1e-9)


def test_rate_limit_bounds_every_tick():
    scene = _load('tendon_6f_8c')
    solver = scene.make_inverse_solver(rate_limit=0.25)
    target = scene.forward(np.array([6.0, 0, 0, 0, 4.0, 0, 0, 0])).effector_positions
    previous = solver.actuation.copy()
    for _ in range(40):
        out = solver.step(target)
        assert np.abs(out.actuation - previous).max() <= 0.25 + 1e-9
        previous = out.actuation
    assert np.abs(solver.effector_positions() - target).max() < 1e-4


@pytest.mark.parametrize('qp_solver', ['active_set', 'proxsuite'])
@pytest.mark.parametrize('relinearize_every', [1, 3])
def test_prepare_moves_the_linearisation_off_the_step_without_changing_it(relinearize_every,
                                                                          qp_solver):
    """prepare() after each step gives the same ticks as linearising inside step()."""
    scene = _load('cbha')
    center = np.asarray(scene.workspace_center)
    angles = np.linspace(0.0, 1.5, 12)
    targets = center + 0.06 * np.stack([0 * angles, np.cos(angles), np.sin(angles)], axis=1)
    # proxsuite keeps its Hessian between ticks of one linearisation (same_hessian): both paths
    plain = scene.make_inverse_solver(relinearize_every=relinearize_every, qp_solver=qp_solver)
    early = scene.make_inverse_solver(relinearize_every=relinearize_every, qp_solver=qp_solver)
    for target in targets:
        expected = plain.step(target[None])
        got = early.step(target[None])
        assert early.prepare()
        np.testing.assert_allclose(got.actuation, expected.actuation, rtol=0, atol=1e-6)
        np.testing.assert_allclose(got.effector_positions, expected.effector_positions,
                                   rtol=0, atol=1e-12)
    assert got.timings['assembly'] == 0.0 and got.timings['factor'] == 0.0


def test_forward_without_the_warning_check_solves_the_same_shape():
    """The CBHA at mid pressure strains a link beyond the small-strain range: a warning."""
    scene = load_scene('cbha')
    actuation = 0.5 * (scene.lower_bounds + scene.upper_bounds)
    checked = scene.forward(actuation, strict=True)
    unchecked = scene.forward(actuation, strict=True, check_warnings=False)
    assert any('strained' in text for text in checked.warnings), checked.warnings
    assert unchecked.warnings == ()
    np.testing.assert_array_equal(unchecked.positions, checked.positions)
    np.testing.assert_array_equal(unchecked.effector_positions, checked.effector_positions)


@pytest.mark.parametrize('written, expected', [
    ('gravity: null', None), ('gravity: [0.0, 0.0, 0.0]', (0.0, 0.0, 0.0)),
    ('', (0.0, 0.0, -9.81)), ('gravity: [0.0, -9.81, 0.0]', (0.0, -9.81, 0.0))])
def test_gravity_null_is_none_and_absent_is_earths(tmp_path, written, expected):
    """``gravity: null`` is no gravity (the tip at rest on the axis), absent is -9.81 along z."""
    text = config_path('scenes', 'tendon_6f_8c.yaml').read_text()
    lines = [line for line in text.splitlines() if not line.startswith('gravity:')]
    (tmp_path / 'scene.yaml').write_text('\n'.join(lines + [written]) + '\n')
    scene = load_scene(tmp_path / 'scene.yaml')
    if expected is None:
        assert scene.gravity is None
    else:
        np.testing.assert_array_equal(scene.gravity, expected)
    tip = scene.rest_effector_positions[-1]
    sag = np.zeros(3) if expected is None else np.asarray(expected)
    if not sag.any():
        # without gravity the backbone stays straight along +x
        np.testing.assert_allclose(tip[1:], 0.0, atol=1e-12)
    else:
        # the tip sags along gravity, and only along it
        assert float(tip @ sag) > 0.0
        across = np.cross(tip - [tip[0], 0.0, 0.0], sag)
        np.testing.assert_allclose(across, 0.0, atol=1e-9)
