"""A scene's calibration block: applied at load by the one scene builder, validated."""

from cbha_inverse.core.actuation.cavities import Cavity, CavityGroup, CavityPart, tube_surface
from cbha_inverse.core.so3 import so3_exp
from cbha_inverse.core.system import EquilibriumSystem
from cbha_inverse.errors import ConfigError
from cbha_inverse.paths import config_path
from cbha_inverse.scene import load_scene
from cbha_inverse.scene.calibration import Calibration
import numpy as np
from oracles.actuation import oracle
import pytest
from scipy.spatial.transform import Rotation
import yaml

PRESSURES = np.array([100e3, 20e3, 20e3, 50e3, 80e3, 10e3])
# an offset of every kind at once: metres away from the origin (beyond the solver's reach
# sphere around the nominal base) and turned about all three axes
POSITION, RPY = (0.8, -0.5, 0.3), (0.3, -0.2, 0.9)


def _scene_file(tmp_path, name='calibrated', **changes):
    """Write a copy of the CBHA scene (segment paths absolute) with keys changed."""
    spec = yaml.safe_load(config_path('scenes', 'cbha.yaml').read_text())
    for item in spec['chain']['sections']:
        item['segment'] = str(config_path('scenes', item['segment']).resolve())
    spec.update(changes)
    path = tmp_path / f'{name}.yaml'
    path.write_text(yaml.safe_dump(spec))
    return path


def _tendon_file(tmp_path, name='tendon', **changes):
    """Write a copy of the two-effector tendon scene (plus an off-axis effector), keys changed."""
    spec = yaml.safe_load(config_path('scenes', 'tendon_10f_16c.yaml').read_text())
    spec['effectors'].append({'name': 'side', 'vertebra': 4, 'offset': [0.005, 0.01, -0.004]})
    spec.update(changes)
    path = tmp_path / f'{name}.yaml'
    path.write_text(yaml.safe_dump(spec))
    return path


def _pose(position, rpy):
    """Return (p, R) of an offset, R from scipy (extrinsic x-y-z = URDF roll-pitch-yaw)."""
    return np.array(position, dtype=float), Rotation.from_euler('xyz', rpy).as_matrix()


def _tensions(scene, seed=3):
    """Return tensions at 10-40 % of every cable's range."""
    rng = np.random.default_rng(seed)
    return scene.upper_bounds * rng.uniform(0.1, 0.4, len(scene.actuator_names))


@pytest.fixture(scope='module')
def nominal():
    return load_scene('cbha')


def test_section_stiffness_divides_that_sections_compliances_only(nominal):
    factors = {'inner': 0.85, 'outer': 1.1}
    scene = load_scene('cbha', calibration=Calibration(factors))
    np.testing.assert_allclose(scene.model.compliances[:8], nominal.model.compliances[:8] / 0.85)
    np.testing.assert_allclose(scene.model.compliances[8:], nominal.model.compliances[8:] / 1.1)
    uniform = load_scene('cbha', calibration=Calibration({'inner': 2.0, 'outer': 2.0}))
    np.testing.assert_allclose(uniform.forward(PRESSURES).effector_positions,
                               load_scene('cbha', stiffness_scale=2.0).forward(
                                   PRESSURES).effector_positions, atol=1e-12)


def test_actuator_gain_is_an_effective_area_factor(tmp_path):
    # a gain g at pressure p / g gives the same load as the nominal cavity at p (exactly)
    gains = {'inner_over': 1.25, 'outer_right': 0.8}
    path = _scene_file(tmp_path, calibration={'actuator_gain': gains})
    plain = load_scene(_scene_file(tmp_path, 'plain'))
    scene = load_scene(path)
    divisor = np.array([gains.get(n, 1.0) for n in scene.actuator_names])
    np.testing.assert_allclose(scene.forward(PRESSURES / divisor).effector_positions,
                               plain.forward(PRESSURES).effector_positions, atol=1e-9)
    moved = scene.forward(PRESSURES).effector_positions - plain.forward(
        PRESSURES).effector_positions
    assert np.linalg.norm(moved) > 1e-3
    assert scene.calibration.actuator_gain == gains


def test_mesh_cavity_gain_scales_wrenches_and_volume():
    surface = tube_surface(0.05, 0.01, (0.0, 0.02, 0.0))
    part = CavityPart(*surface, 0, np.array([0.05, 0.0, 0.0]), np.eye(3))
    plain = CavityGroup([Cavity('c', (part,), 1e5)], 2)
    scaled = CavityGroup([Cavity('c', (part,), 1e5, gain=0.7)], 2)
    positions = np.array([[0.0, 0.0, 0.0], [0.05, 0.003, 0.0]])
    rotations = np.stack([np.eye(3), so3_exp(np.array([0.0, 0.0, 0.1]))])
    wrenches, volumes = plain.evaluate(positions, rotations)
    wrenches_scaled, volumes_scaled = scaled.evaluate(positions, rotations)
    assert np.abs(wrenches).max() > 1e-6
    np.testing.assert_allclose(wrenches_scaled, 0.7 * wrenches, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(volumes_scaled, 0.7 * volumes, rtol=1e-12)


def test_tip_payload_is_a_mass_load_at_the_last_frame_and_lowers_the_tip(tmp_path, nominal):
    scene = load_scene(_scene_file(tmp_path, calibration={'tip_payload_mass': 0.05}))
    np.testing.assert_array_equal(scene.model.masses, nominal.model.masses)
    (payload,) = scene.loads.items
    assert (payload.name, payload.frame, payload.mass) == ('tip_payload_mass', 'tip', 0.05)
    rest = np.zeros(6)
    drop = (scene.forward(rest).effector_positions - nominal.forward(rest).effector_positions)[0]
    assert drop[2] < -1e-3


def test_calibration_on_top_of_the_file_multiplies(tmp_path):
    path = _scene_file(tmp_path, calibration={'section_stiffness': {'inner': 0.5}})
    scene = load_scene(path, calibration=Calibration({'inner': 3.0, 'outer': 2.0}))
    assert scene.calibration.section_stiffness == {'inner': 1.5, 'outer': 2.0}


def test_cable_gain_equals_the_command_times_the_gain(tmp_path):
    # cables are tension (force) controlled: a gain g at tension t pulls like the nominal cable
    # at g t (column, load and load stiffness alike), under gravity
    gains = {'v5_67': 1.4, 'v2_0': 0.6, 'v4_225': 1.15}
    scene = load_scene(_tendon_file(tmp_path, calibration={'actuator_gain': gains}))
    plain = load_scene(_tendon_file(tmp_path, 'plain'))
    tensions = _tensions(scene)
    factor = np.array([gains.get(n, 1.0) for n in scene.actuator_names])
    gained = scene.forward(tensions, strict=True)
    reference = plain.forward(tensions * factor, strict=True)
    np.testing.assert_allclose(gained.effector_positions, reference.effector_positions,
                               rtol=0, atol=1e-10)
    np.testing.assert_allclose(gained.positions, reference.positions, rtol=0, atol=1e-10)
    moved = gained.effector_positions - plain.forward(tensions, strict=True).effector_positions
    assert np.abs(moved).max() > 1e-3
    assert scene.calibration.actuator_gain == gains
    np.testing.assert_array_equal(scene.upper_bounds, plain.upper_bounds)  # bounds: commands


def test_cable_gain_reaches_the_tick_system_like_the_oracle(tmp_path):
    """The compiled tick (residual, columns, tangent) of gained cables against the numpy oracle."""
    gains = {'v5_67': 1.4, 'v2_0': 0.6}
    scene = load_scene(_tendon_file(tmp_path, calibration={'actuator_gain': gains}))
    plain = load_scene(_tendon_file(tmp_path, 'plain'))
    state = scene.forward(_tensions(scene), strict=True)
    actuation = _tensions(scene, seed=4)
    external = np.zeros(6 * scene.model.n_links)
    column = {name: 1 + k for k, name in enumerate(scene.actuator_names)}
    systems = [EquilibriumSystem(s.model, s.actuators, external) for s in (scene, plain)]
    (tangent, rhs), (_, plain_rhs) = (
        tick.linearise(state.positions, state.rotations, actuation) for tick in systems)
    for name, gain in gains.items():
        reference = gain * plain_rhs[:, column[name]]
        np.testing.assert_allclose(rhs[:, column[name]], reference, rtol=0,
                                   atol=1e-14 * np.abs(reference).max())
    loads = oracle(scene.actuators).loads(state.positions, state.rotations, actuation)[1:]
    np.testing.assert_allclose(rhs[:, 1:] @ actuation, loads.reshape(-1), rtol=0,
                               atol=1e-12 * np.abs(loads).max())
    reference = oracle(scene.actuators).load_tangent(state.positions, state.rotations, actuation)
    load = systems[0].dense(tangent) - systems[1].dense(
        systems[1].linearise(state.positions, state.rotations, np.zeros_like(actuation))[0])
    np.testing.assert_allclose(load, np.tril(reference), rtol=0,
                               atol=1e-11 * np.abs(reference).max())


@pytest.mark.parametrize('name', ['tendon', 'cbha'])
def test_position_offset_shifts_every_frame_and_effector_by_the_vector(tmp_path, name):
    # without gravity the statics is invariant under a rigid motion of the base
    write = _tendon_file if name == 'tendon' else _scene_file
    block = {'base_offset': {'position': list(POSITION)}}
    scene = load_scene(write(tmp_path, calibration=block), gravity=[0.0, 0.0, 0.0])
    plain = load_scene(write(tmp_path, 'plain'), gravity=[0.0, 0.0, 0.0])
    actuation = PRESSURES if name == 'cbha' else _tensions(scene)
    moved, nominal = scene.forward(actuation, strict=True), plain.forward(actuation, strict=True)
    np.testing.assert_allclose(moved.effector_positions - nominal.effector_positions,
                               np.broadcast_to(POSITION, nominal.effector_positions.shape),
                               rtol=0, atol=1e-9)
    np.testing.assert_allclose(moved.positions - nominal.positions,
                               np.broadcast_to(POSITION, nominal.positions.shape), rtol=0,
                               atol=1e-9)
    np.testing.assert_allclose(moved.quaternions, nominal.quaternions, rtol=0, atol=1e-9)


def test_yaw_offset_turns_the_tip_about_the_base_z_axis(tmp_path):
    yaw = 0.7
    rz = np.array([[np.cos(yaw), -np.sin(yaw), 0.0], [np.sin(yaw), np.cos(yaw), 0.0],
                   [0.0, 0.0, 1.0]])
    block = {'base_offset': {'rpy': [0.0, 0.0, yaw]}}
    scene = load_scene(_tendon_file(tmp_path, calibration=block), gravity=[0.0, 0.0, 0.0])
    plain = load_scene(_tendon_file(tmp_path, 'plain'), gravity=[0.0, 0.0, 0.0])
    tensions = _tensions(scene)
    tip = plain.forward(tensions, strict=True).effector_positions
    np.testing.assert_allclose(scene.forward(tensions, strict=True).effector_positions,
                               tip @ rz.T, rtol=0, atol=1e-9)
    assert np.abs(tip @ rz.T - tip).max() > 1e-2


@pytest.mark.parametrize('name', ['tendon', 'cbha'])
def test_offset_scene_is_the_nominal_one_under_turned_gravity_then_moved(tmp_path, name):
    """
    Gravity stays in base_frame: the chain sees it turned by R^T; the result is moved by T.

    The reference is the nominal scene solved with gravity R^T g in its own axes, its frames
    mapped by ``x -> R x + p``, ``R_f -> R R_f``.
    """
    write = _tendon_file if name == 'tendon' else _scene_file
    block = {'base_offset': {'position': list(POSITION), 'rpy': list(RPY)}}
    scene = load_scene(write(tmp_path, calibration=block))
    p, rot = _pose(POSITION, RPY)
    nominal = load_scene(write(tmp_path, 'plain'), gravity=rot.T @ scene.gravity)
    actuation = PRESSURES if name == 'cbha' else _tensions(scene)
    moved = scene.forward(actuation, strict=True)
    reference = nominal.forward(actuation, strict=True)
    np.testing.assert_allclose(moved.effector_positions, reference.effector_positions @ rot.T + p,
                               rtol=0, atol=1e-9)
    np.testing.assert_allclose(moved.positions, reference.positions @ rot.T + p, rtol=0,
                               atol=1e-9)
    turned = Rotation.from_matrix(rot) * Rotation.from_quat(reference.quaternions)
    np.testing.assert_allclose(Rotation.from_quat(moved.quaternions).as_matrix(),
                               turned.as_matrix(), rtol=0, atol=1e-9)
    # gravity did not turn with the base: the same scene without the turn of g differs
    unturned = load_scene(write(tmp_path, 'plain')).forward(actuation, strict=True)
    assert np.abs(unturned.effector_positions @ rot.T + p - moved.effector_positions).max() > 1e-4


def test_inverse_solver_and_workspace_centre_follow_the_offset(tmp_path):
    """
    The tick tracks targets in base_frame, around the moved base.

    The offset scene's actuation toward ``T(target)`` equals the nominal one's toward
    ``target`` (under turned gravity); the reach sphere is centred on the moved base (the offset
    lies outside the one around the origin, so a sphere there would clamp the targets).
    """
    block = {'base_offset': {'position': list(POSITION), 'rpy': list(RPY)}}
    scene = load_scene(_tendon_file(tmp_path, calibration=block))
    p, rot = _pose(POSITION, RPY)
    nominal = load_scene(_tendon_file(tmp_path, 'plain'), gravity=rot.T @ scene.gravity)
    np.testing.assert_allclose(scene.workspace_center, nominal.workspace_center @ rot.T + p,
                               rtol=0, atol=1e-9)
    targets = nominal.workspace_center + [[0.0, 0.004, -0.003]] * 3
    solvers = scene.make_inverse_solver(), nominal.make_inverse_solver()
    for _ in range(15):
        out = solvers[0].step(targets @ rot.T + p)
        reference = solvers[1].step(targets)
    assert out.warnings == reference.warnings == ()
    np.testing.assert_allclose(out.actuation, reference.actuation, rtol=0,
                               atol=1e-7 * scene.upper_bounds.max())
    np.testing.assert_allclose(out.effector_positions, reference.effector_positions @ rot.T + p,
                               rtol=0, atol=1e-9)
    assert np.linalg.norm(reference.effector_positions - nominal.rest_effector_positions) > 1e-3


def test_explicit_workspace_centre_moves_with_the_base(tmp_path):
    center = [0.2, 0.01, -0.02]
    block = {'base_offset': {'position': list(POSITION), 'rpy': list(RPY)}}
    scene = load_scene(_tendon_file(tmp_path, calibration=block, workspace_center=center))
    p, rot = _pose(POSITION, RPY)
    np.testing.assert_allclose(scene.workspace_center[-1], rot @ center + p, rtol=0, atol=1e-15)
    np.testing.assert_allclose(scene.workspace_center[:-1], scene.rest_effector_positions[:-1])


def test_combined_offsets_compose_other_in_the_axes_of_self(tmp_path):
    # T = T_self T_other: p = p_self + R_self p_other, R = R_self R_other (not commutative)
    first = {'position': [0.01, -0.02, 0.03], 'rpy': [0.1, 0.2, -0.3]}
    second = Calibration(base_position=(0.02, 0.0, -0.01), base_rpy=(-0.2, 0.05, 0.4))
    scene = load_scene(_tendon_file(tmp_path, calibration={'base_offset': first}),
                       calibration=second)
    p1, r1 = _pose(first['position'], first['rpy'])
    p2, r2 = _pose(second.base_position, second.base_rpy)
    np.testing.assert_allclose(scene.model.base_position, p1 + r1 @ p2, rtol=0, atol=1e-15)
    np.testing.assert_allclose(scene.model.base_rotation, r1 @ r2, rtol=0, atol=1e-15)
    np.testing.assert_allclose(Rotation.from_euler('xyz', scene.calibration.base_rpy).as_matrix(),
                               r1 @ r2, rtol=0, atol=1e-15)
    assert np.abs(r2 @ r1 - r1 @ r2).max() > 1e-2      # the order is observable
    assert np.abs((p2 + r2 @ p1) - (p1 + r1 @ p2)).max() > 1e-3
    assert Calibration().combined(second) == second
    assert second.combined(None) is second


def test_as_yaml_round_trips_through_a_scene_file(tmp_path):
    calibration = Calibration({}, {'v5_67': 1.3, 'v2_0': 0.9}, 0.01, (0.1, -0.2, 1.0 / 3.0),
                              (0.25, -1.0 / 7.0, 3.0))
    path = _tendon_file(tmp_path, calibration=calibration.as_yaml())
    scene = load_scene(path)
    assert scene.calibration == calibration
    np.testing.assert_allclose(scene.model.base_position, calibration.base_position, atol=0)
    np.testing.assert_allclose(scene.model.base_rotation,
                               Rotation.from_euler('xyz', calibration.base_rpy).as_matrix(),
                               rtol=0, atol=1e-15)
    on_top = load_scene(_tendon_file(tmp_path, 'plain'), calibration=calibration)
    np.testing.assert_array_equal(scene.forward(_tensions(scene)).effector_positions,
                                  on_top.forward(_tensions(scene)).effector_positions)
    identity = Calibration().as_yaml()
    assert identity['base_offset'] == {'position': [0.0, 0.0, 0.0], 'rpy': [0.0, 0.0, 0.0]}
    assert load_scene(_tendon_file(tmp_path, 'identity', calibration=identity)).calibration == (
        Calibration())


@pytest.mark.parametrize('field_name, value', [('base_position', (0.0, 1.0)),
                                               ('base_rpy', (0.0, float('nan'), 0.0)),
                                               ('base_position', (0.0, float('inf'), 0.0))])
def test_calibration_refuses_a_bad_offset(field_name, value):
    with pytest.raises(ValueError, match=f'{field_name} must be 3 finite numbers'):
        Calibration(**{field_name: value})


@pytest.mark.parametrize('block, key, problem', [
    ({'actuator_gain': {'inner_over': 1.1}}, 'calibration.actuator_gain.inner_over',
     'no actuator'),
    ({'actuator_gain': {'v5_67': 0.0}}, 'calibration.actuator_gain.v5_67', '> 0'),
    ({'actuator_gain': {'v5_67': float('inf')}}, 'calibration.actuator_gain.v5_67', 'finite'),
    ({'base_offset': {'position': [0.0, 0.1]}}, 'calibration.base_offset.position',
     'list of 3 finite numbers'),
    ({'base_offset': {'rpy': [0.0, float('nan'), 0.0]}}, 'calibration.base_offset.rpy',
     'list of 3 finite numbers'),
    ({'base_offset': {'rpy': [0.0, 'a', 0.0]}}, 'calibration.base_offset.rpy',
     'list of 3 finite numbers'),
    ({'base_offset': {'position': 0.1}}, 'calibration.base_offset.position',
     'list of 3 finite numbers'),
    ({'base_offset': {'translation': [0.0, 0.0, 0.0]}}, 'calibration.base_offset.translation',
     'unknown key (valid: position, rpy)'),
    ({'base_offset': [0.0, 0.0, 0.0]}, 'calibration.base_offset', 'mapping'),
])
def test_bad_cable_gain_or_offset_names_the_file_and_key(tmp_path, block, key, problem):
    path = _tendon_file(tmp_path, calibration=block)
    with pytest.raises(ConfigError) as info:
        load_scene(path)
    assert info.value.path == str(path)
    assert info.value.key == key
    assert problem in info.value.problem


@pytest.mark.parametrize('block, key, problem', [
    ({'section_stiffness': {'inner': -1.0}}, 'calibration.section_stiffness.inner', '> 0'),
    ({'section_stiffness': {'inner': float('nan')}}, 'section_stiffness.inner', 'finite'),
    ({'section_stiffness': {'middle': 1.0}}, 'section_stiffness.middle', 'no chain section'),
    ({'actuator_gain': {'wrist': 1.0}}, 'calibration.actuator_gain.wrist', 'no actuator'),
    ({'actuator_gain': {'inner_over': 'big'}}, 'actuator_gain.inner_over', 'number'),
    ({'tip_payload_mass': -0.1}, 'calibration.tip_payload_mass', '>= 0'),
    ({'stiffness': 1.0}, 'calibration.stiffness', 'unknown key'),
])
def test_bad_calibration_names_the_file_and_key(tmp_path, block, key, problem):
    path = _scene_file(tmp_path, calibration=block)
    with pytest.raises(ConfigError) as info:
        load_scene(path)
    assert info.value.path == str(path)
    assert key in info.value.key
    assert problem in info.value.problem


def test_beam_scene_has_no_sections_to_calibrate(tmp_path):
    spec = yaml.safe_load(config_path('scenes', 'tendon_6f_8c.yaml').read_text())
    spec['calibration'] = {'section_stiffness': {'inner': 1.1}}
    path = tmp_path / 'tendon.yaml'
    path.write_text(yaml.safe_dump(spec))
    with pytest.raises(ConfigError, match='no chain section'):
        load_scene(path)
