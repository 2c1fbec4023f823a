"""The simulated string pots: readings of the plant's true shape with its own calibration."""

from cbha_inverse.scene import load_scene
from cbha_inverse.sim.pots import per_pot, SimulatedPots
import numpy as np
import pytest


@pytest.fixture(scope='module')
def bent():
    scene = load_scene('cbha')
    return scene, scene.forward([1e5, 0.0, 0.0, 0.0, 5e4, 0.0], strict=True)


def test_noise_free_readings_are_the_scene_readings(bent):
    scene, result = bent
    pots = SimulatedPots(scene.sensors, noise_std=0.0)
    lengths = scene.sensors.lengths(result.positions, result.rotations)
    np.testing.assert_allclose(pots.read(result.positions, result.rotations),
                               1000.0 * lengths, rtol=1e-14)
    assert pots.names == scene.sensors.names


def test_the_plants_own_calibration_and_noise(bent):
    scene, result = bent
    lengths = scene.sensors.lengths(result.positions, result.rotations)
    pots = SimulatedPots(scene.sensors, offset=[5.0], gain=[900.0] * 6, noise_std=1e-4, seed=3)
    readings = np.array([pots.read(result.positions, result.rotations) for _ in range(400)])
    np.testing.assert_allclose(readings.mean(axis=0), 5.0 + 900.0 * lengths, atol=0.02)
    np.testing.assert_allclose(readings.std(axis=0), 0.09, rtol=0.15)
    again = SimulatedPots(scene.sensors, offset=[5.0], gain=[900.0], noise_std=1e-4, seed=3)
    np.testing.assert_array_equal(again.read(result.positions, result.rotations), readings[0])
    # the scene's own calibration is left alone
    np.testing.assert_allclose(scene.sensors.reading_offset, 0.0)


@pytest.mark.parametrize('kwargs, match', [
    ({'offset': [1.0, 2.0]}, 'string_pot_offset'), ({'gain': [0.0]}, 'string_pot_gain'),
    ({'gain': [np.nan]}, 'string_pot_gain'), ({'noise_std': -1.0}, 'noise_std')])
def test_bad_parameters_are_refused(bent, kwargs, match):
    with pytest.raises(ValueError, match=match):
        SimulatedPots(bent[0].sensors, **kwargs)


def test_per_pot_broadcasts_one_value():
    np.testing.assert_array_equal(per_pot('x', [2.0], 3), [2.0, 2.0, 2.0])


def test_a_stuck_pot_keeps_its_last_reading_while_the_others_move(bent):
    scene, result = bent
    rest = scene.forward(np.zeros(6), strict=True)
    pots = SimulatedPots(scene.sensors, noise_std=0.0, stuck_pot=2)
    before = pots.read(rest.positions, rest.rotations)
    stuck = pots.read(result.positions, result.rotations, stuck=True)
    truth = 1000.0 * scene.sensors.lengths(result.positions, result.rotations)
    # the stuck pot reads what it read at rest; the others read the bent shape
    assert stuck[2] == before[2] and abs(truth[2] - before[2]) > 1.0
    np.testing.assert_allclose(np.delete(stuck, 2), np.delete(truth, 2), rtol=1e-14)
    again = pots.read(rest.positions, rest.rotations, stuck=True)
    assert again[2] == before[2]
    pots.unstick()
    np.testing.assert_allclose(pots.read(result.positions, result.rotations), truth, rtol=1e-14)


def test_a_stuck_pot_needs_an_index_of_the_scene(bent):
    with pytest.raises(ValueError, match='string_pot_stuck'):
        SimulatedPots(bent[0].sensors, stuck_pot=6)
