"""The scenes' ``sensors`` block: the CBHA's six string pots, their order, routing, calibration."""

from pathlib import Path

from cbha_inverse.config_files import read_yaml
from cbha_inverse.errors import ConfigError
from cbha_inverse.paths import config_path
from cbha_inverse.robot.robotino import ARM_VALVES
from cbha_inverse.scene import load_scene
import numpy as np
import pytest


@pytest.fixture(scope='module')
def cbha():
    return load_scene('cbha')


def test_the_cbha_pots_are_in_the_drivers_order(cbha):
    bridge = read_yaml(config_path('robotino_bridge.yaml'))['/**']['ros__parameters']
    assert cbha.sensors.names == tuple(bridge['string_pot_names'])
    assert cbha.sensors.names == tuple(f'string_pot_{valve}' for valve in ARM_VALVES)
    assert cbha.actuator_names == ARM_VALVES


def test_each_tube_lengthens_its_own_pot_most(cbha):
    """Pressure in one tube lengthens that tube's pot the most of its section's three pots."""
    pots = cbha.sensors
    rest = cbha.forward(np.zeros(6), strict=True).state
    rest_lengths = pots.lengths(rest.positions, rest.rotations)
    for valve in range(6):
        pressure = np.zeros(6)
        pressure[valve] = 1.0e5
        state = cbha.forward(pressure, strict=True).state
        change = pots.lengths(state.positions, state.rotations) - rest_lengths
        section = slice(0, 3) if valve < 3 else slice(3, 6)
        assert np.argmax(change[section]) == valve % 3, (valve, change)
        if valve < 3:
            # an inner tube moves the outer pots by the same change in the inner section
            np.testing.assert_allclose(change[3:], change[:3], atol=2e-4)
        else:
            # an outer tube does not move the inner pots (beyond the sag of the load)
            assert np.abs(change[:3]).max() < 0.05 * np.abs(change[3:]).max()


def test_the_cbha_rest_readings_match_the_reported_pot_lengths(cbha):
    """The authors' controller reports about 100-110 mm (inner) and 192-198 mm (outer)."""
    rest = cbha.forward(np.zeros(6), strict=True).state
    readings = cbha.sensors.readings(cbha.sensors.lengths(rest.positions, rest.rotations))
    assert np.all((readings[:3] > 0.95 * 100.0) & (readings[:3] < 1.05 * 110.0)), readings
    assert np.all((readings[3:] > 0.95 * 192.0) & (readings[3:] < 1.05 * 198.0)), readings
    np.testing.assert_allclose(cbha.sensors.noise_std, 1e-4)


@pytest.mark.parametrize('name', ['tendon_6f_8c', 'tendon_10f_16c'])
def test_a_scene_without_sensors_builds_none(name):
    assert load_scene(name).sensors is None


def _scene_with(tmp_path, sensors):
    text = Path(config_path('scenes', 'tendon_6f_8c.yaml')).read_text()
    path = tmp_path / 'scene.yaml'
    path.write_text(text + '\nsensors:\n' + sensors)
    return path


def test_explicit_attachment_points_equal_the_vertebra_route(tmp_path):
    path = _scene_with(tmp_path, (
        '  - {name: a, kind: string_pot, angle_deg: 90.0, radius: 0.01, end_vertebra: 2,\n'
        '     offset: 5.0, gain: 1000.0, noise_std: 2.0e-4}\n'
        '  - {name: b, kind: string_pot, points: [{vertebra: 0, offset: [0.0, 0.0, 0.01]},\n'
        '     {vertebra: 1, offset: [0.0, 0.0, 0.01]},\n'
        '     {vertebra: 2, offset: [0.0, 0.0, 0.01]}]}\n'))
    scene = load_scene(path)
    state = scene.forward(0.5 * scene.upper_bounds, strict=True).state
    lengths = scene.sensors.lengths(state.positions, state.rotations)
    np.testing.assert_allclose(lengths[0], lengths[1], rtol=1e-12)
    np.testing.assert_allclose(scene.sensors.reading_offset, [5.0, 0.0])
    np.testing.assert_allclose(scene.sensors.reading_gain, [1000.0, 1.0])
    np.testing.assert_allclose(scene.sensors.noise_std, [2e-4, 1e-4])


@pytest.mark.parametrize('sensor, match', [
    ('{name: a, kind: camera, angle_deg: 0.0, radius: 0.01, end_vertebra: 2}', 'kind'),
    ('{name: a, kind: string_pot, angle_deg: 0.0, radius: 0.01, end_vertebra: 99}',
     'end_vertebra'),
    ('{name: a, kind: string_pot, angle_deg: 0.0, radius: 0.01, end_vertebra: 2, gain: 0.0}',
     'gain'),
    ('{name: a, kind: string_pot, points: [{vertebra: 0}]}', 'points'),
])
def test_a_broken_sensor_names_the_file_and_key(tmp_path, sensor, match):
    path = _scene_with(tmp_path, f'  - {sensor}\n')
    with pytest.raises(ConfigError, match=match) as info:
        load_scene(path)
    assert 'scene.yaml' in str(info.value)
