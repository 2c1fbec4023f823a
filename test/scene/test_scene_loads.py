"""A scene's ``loads`` block: read into Scene.loads, applied by the forward model, validated."""

from cbha_inverse.core.loads import Load, Loads
from cbha_inverse.errors import ConfigError
from cbha_inverse.paths import config_path
from cbha_inverse.scene import load_scene
from cbha_inverse.scene.calibration import Calibration
from cbha_inverse.scene.cli import main as scene_main
from cbha_inverse.scene.refinement import refined_beam_data
import numpy as np
import pytest
import yaml

TENSIONS = np.zeros(8)


def _tendon_file(tmp_path, **changes):
    """Write a copy of the tendon_6f_8c scene with keys changed."""
    spec = yaml.safe_load(config_path('scenes', 'tendon_6f_8c.yaml').read_text())
    spec.update(changes)
    path = tmp_path / 'loaded.yaml'
    path.write_text(yaml.safe_dump(spec))
    return path


LOADS = [{'name': 'push', 'frame': 'tip', 'force': [0.0, 0.2, 0.0], 'torque': [0.0, 0.0, 0.01]},
         {'name': 'thrust', 'vertebra': 2, 'force': [0.0, 0.0, 0.3], 'in': 'local'},
         {'name': 'tool', 'frame': 3, 'mass': 0.02}]


def test_the_loads_block_becomes_the_scenes_loads_and_the_forward_models(tmp_path):
    scene = load_scene(_tendon_file(tmp_path, loads=LOADS))
    expected = Loads((Load.of_wrench('push', 6, [0.0, 0.2, 0.0], [0.0, 0.0, 0.01]),
                      Load.of_wrench('thrust', 4, [0.0, 0.0, 0.3], axes='local'),
                      Load.of_mass('tool', 3, 0.02)))
    assert scene.loads == expected
    plain = load_scene('tendon_6f_8c')
    np.testing.assert_array_equal(
        scene.forward(TENSIONS, strict=True).positions,
        plain.forward(TENSIONS, loads=expected, strict=True).positions)
    unloaded = scene.forward(TENSIONS, loads=Loads(), strict=True).positions
    np.testing.assert_array_equal(unloaded, plain.forward(TENSIONS, strict=True).positions)
    assert np.abs(scene.forward(TENSIONS).positions - unloaded).max() > 1e-3
    with pytest.raises(ValueError, match='Loads'):
        scene.forward(TENSIONS, loads=[Load.of_mass('tool', 3, 0.02)])
    with pytest.raises(ValueError, match='outside'):
        scene.forward(TENSIONS, loads=Loads((Load.of_mass('tool', 7, 0.02),)))


def test_tip_payload_mass_is_the_same_load_as_a_mass_in_the_block(tmp_path):
    by_block = load_scene(_tendon_file(tmp_path, loads=[{'name': 'p', 'mass': 0.03}]))
    by_calibration = load_scene('tendon_6f_8c', calibration=Calibration(tip_payload_mass=0.03))
    np.testing.assert_array_equal(by_block.forward(TENSIONS, strict=True).positions,
                                  by_calibration.forward(TENSIONS, strict=True).positions)
    # the controller built from the scene carries it too
    solver = by_calibration.make_inverse_solver()
    assert solver.loads == by_calibration.loads


@pytest.mark.parametrize('loads, key, problem', [
    ([{'name': 'a', 'frame': 'tip', 'forse': [0, 0, 1]}], 'loads[0].forse',
     "did you mean 'force'"),
    ([{'name': 'a', 'frame': 'tip', 'force': [0, 0]}], 'loads[0].force', '3 finite numbers'),
    ([{'name': 'a', 'frame': 'tip', 'force': [0, 0, 1], 'in': 'tool'}], 'loads[0].in',
     'must be one of'),
    ([{'name': 'a', 'frame': 0, 'force': [0, 0, 1]}], 'loads[0].frame', 'base'),
    ([{'name': 'a', 'vertebra': 4, 'force': [0, 0, 1]}], 'loads[0].vertebra', 'outside'),
    ([{'name': 'a', 'frame': 2, 'vertebra': 1, 'mass': 0.1}], 'loads[0].vertebra', 'not both'),
    ([{'name': 'a', 'frame': 2, 'mass': 0.1, 'force': [0, 0, 1]}], 'loads[0].force', 'not both'),
    ([{'name': 'a', 'frame': 2, 'mass': -0.1}], 'loads[0].mass', '>= 0'),
    ([{'name': 'a', 'frame': 2}], 'loads[0].force', 'force, torque or mass'),
    ([{'name': 'a', 'mass': 0.1}, {'name': 'a', 'mass': 0.2}], 'loads[1].name', 'named twice'),
    ([{'frame': 2, 'mass': 0.1}], 'loads[0].name', 'missing'),
])
def test_a_wrong_load_names_its_file_and_key(tmp_path, loads, key, problem):
    path = _tendon_file(tmp_path, loads=loads)
    with pytest.raises(ConfigError, match=problem) as caught:
        load_scene(path)
    assert caught.value.key == key and caught.value.path == str(path)


def test_a_mass_in_a_scene_without_gravity_is_refused(tmp_path):
    path = _tendon_file(tmp_path, gravity=None, loads=[{'name': 'p', 'frame': 2, 'mass': 0.1}])
    with pytest.raises(ConfigError, match='needs gravity') as caught:
        load_scene(path)
    assert caught.value.key == 'loads[0].mass'
    path = _tendon_file(tmp_path, gravity=None, calibration={'tip_payload_mass': 0.1})
    with pytest.raises(ConfigError, match='needs gravity'):
        load_scene(path)


def test_scene_check_prints_the_loaded_pose(capsys):
    assert scene_main(['check', 'tendon_6f_8c', '--load', 'push=0,0,-0.5@tip']) == 0
    loaded = capsys.readouterr().out
    assert scene_main(['check', 'tendon_6f_8c']) == 0
    plain = capsys.readouterr().out
    scene = load_scene('tendon_6f_8c')
    tip = scene.forward(np.zeros(8), loads=scene.loads.updated(
        Load.of_wrench('push', 'tip', [0.0, 0.0, -0.5])), strict=True).effector_positions[-1]
    assert 'load push' in loaded and 'push' not in plain
    assert f'effector tip: [{", ".join(f"{1e3 * v:.3f}" for v in tip)}] mm' in loaded


@pytest.mark.parametrize('spec, problem', [
    ('push=0,0,nan@tip', 'finite'), ('push=0,0@tip', '3 or 6'), ('push=0,0,1', 'FRAME'),
    ('0,0,1@tip', 'NAME'), ('push=0,0,1@40', 'outside'), ('push=0,0,1@tip:tool', 'base or local'),
    ('push=-1@tip', 'mass'),
])
def test_scene_check_refuses_a_bad_load_in_one_line(spec, problem, capsys):
    with pytest.raises(SystemExit) as stopped:
        scene_main(['check', 'tendon_6f_8c', '--load', spec])
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert stopped.value.code == 2 and problem in last and f'--load {spec}' in last, last


def test_a_refined_chain_keeps_a_load_on_the_same_point_of_the_backbone(tmp_path):
    loads = [{'name': 'a', 'frame': 3, 'force': [0, 0, -0.2]},
             {'name': 'b', 'vertebra': 1, 'mass': 0.01},
             {'name': 'c', 'frame': 'tip', 'mass': 0.01}]
    refined = refined_beam_data(yaml.safe_load(_tendon_file(tmp_path, loads=loads).read_text()))
    assert [item.get('frame', item.get('vertebra')) for item in refined['loads']] == [6, 1, 'tip']
