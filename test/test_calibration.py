"""A scene's calibration block: applied at load by the one scene builder, validated."""

from cbha_inverse.core.actuation.cavities import Cavity, CavityGroup, CavityPart, tube_surface
from cbha_inverse.core.se3 import so3_exp
from cbha_inverse.errors import ConfigError
from cbha_inverse.paths import config_path
from cbha_inverse.ros.cbha_sim_node import plant_errors
from cbha_inverse.scene import load_scene
from cbha_inverse.scene.calibration import Calibration
import numpy as np
import pytest
import yaml

PRESSURES = np.array([100e3, 20e3, 20e3, 50e3, 80e3, 10e3])


def _scene_file(tmp_path, name='calibrated', **changes):
    """Write a copy of the CBHA scene (segment paths absolute) with keys changed."""
    spec = yaml.safe_load(config_path('scenes', 'cbha.yaml').read_text())
    for item in spec['chain']['sections']:
        item['segment'] = str(config_path('scenes', item['segment']).resolve())
    spec.update(changes)
    path = tmp_path / f'{name}.yaml'
    path.write_text(yaml.safe_dump(spec))
    return path


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


def test_tip_payload_adds_mass_at_the_last_frame_and_lowers_the_tip(tmp_path, nominal):
    scene = load_scene(_scene_file(tmp_path, calibration={'tip_payload_mass': 0.05}))
    np.testing.assert_allclose(scene.model.masses - nominal.model.masses,
                               np.r_[np.zeros(15), 0.05])
    rest = np.zeros(6)
    drop = (scene.forward(rest).effector_positions - nominal.forward(rest).effector_positions)[0]
    assert drop[2] < -1e-3


def test_calibration_on_top_of_the_file_multiplies(tmp_path):
    path = _scene_file(tmp_path, calibration={'section_stiffness': {'inner': 0.5}})
    scene = load_scene(path, calibration=Calibration({'inner': 3.0, 'outer': 2.0}))
    assert scene.calibration.section_stiffness == {'inner': 1.5, 'outer': 2.0}


@pytest.mark.parametrize('block, key, problem', [
    ({'section_stiffness': {'inner': -1.0}}, 'calibration.section_stiffness.inner', '> 0'),
    ({'section_stiffness': {'inner': float('nan')}}, 'section_stiffness.inner', 'finite'),
    ({'section_stiffness': {'middle': 1.0}}, 'section_stiffness.middle', 'no chain section'),
    ({'actuator_gain': {'wrist': 1.0}}, 'calibration.actuator_gain.wrist', 'no cavity'),
    ({'actuator_gain': {'inner_over': 'big'}}, 'actuator_gain.inner_over', 'number'),
    ({'tip_payload_mass': -0.1}, 'calibration.tip_payload_mass', '>= 0'),
    ({'stiffness': 1.0}, 'calibration.stiffness', 'unknown calibration key'),
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


def test_plant_errors_map_the_sim_parameters_by_name():
    valves = ('b', 'a')
    errors = plant_errors(('inner', 'outer'), valves, (0.85, 1.0), (0.9, 1.1))
    assert errors.section_stiffness == {'inner': 0.85}
    assert errors.actuator_gain == {'b': 0.9, 'a': 1.1}
    assert plant_errors(('inner', 'outer'), valves, (2.0,), (1.0,)).section_stiffness == {
        'inner': 2.0, 'outer': 2.0}
    assert plant_errors((), valves, (1.0,), (1.0,)) == Calibration()
    with pytest.raises(ValueError, match='section_stiffness_scale needs 1 or 2'):
        plant_errors(('inner', 'outer'), valves, (1.0, 1.0, 1.0), (1.0,))
    with pytest.raises(ValueError, match='section_stiffness_scale needs'):
        plant_errors((), valves, (0.9,), (1.0,))
    with pytest.raises(ValueError, match='cavity_gain_scale must be finite'):
        plant_errors(('inner',), valves, (1.0,), (0.0, 1.0))
