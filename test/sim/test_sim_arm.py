"""The simulated arm behind cbha_sim: valve order, valve line, plant and seeded sensor noise."""

from cbha_inverse.paths import config_path
from cbha_inverse.scene import load_scene
from cbha_inverse.sim.arm import SimulatedArm
from cbha_inverse.sim.plant import StaticPlant
from cbha_inverse.sim.valves import ValveLine
import numpy as np
import pytest

LATENCY = 0.003
TAU = 0.01
SEED = 7


@pytest.fixture(scope='module')
def scene():
    return load_scene('tendon_6f_8c')


def _arm(scene, order, **noise):
    return SimulatedArm(scene, order, latency=LATENCY, valve_time_constant=TAU, seed=SEED,
                        tolerance=1e-9, **noise)


def test_commands_in_valve_order_drive_the_scene_actuators(scene):
    """Valve k drives scene actuator order[k]; the valves follow the line's delayed first order."""
    m = len(scene.actuator_names)
    order = np.roll(np.arange(m), 1)          # a cyclic shift: not its own inverse
    command = np.linspace(0.5, 3.0, m)      # N, valve order
    arm = _arm(scene, order)
    line = ValveLine(m, LATENCY, TAU)
    in_scene_order = np.empty(m)
    in_scene_order[order] = command
    arm.send(0.0, command)
    line.send(0.0, in_scene_order)
    for time in (0.002, 0.005, 0.02, 1.0):
        measured = arm.advance(time)
        expected = line.advance(time)
        np.testing.assert_array_equal(arm.pressures, expected)          # scene order
        np.testing.assert_array_equal(measured, expected[order])        # valve order, no noise
    np.testing.assert_allclose(measured, command, rtol=1e-12)
    result, tip = arm.update_plant()
    reference = StaticPlant(scene, tolerance=1e-9).update(in_scene_order)
    assert result.converged
    np.testing.assert_allclose(result.effector_positions, reference.effector_positions,
                               atol=1e-12)
    np.testing.assert_array_equal(tip, result.effector_positions[-1])   # tip_noise 0
    arm.reset()
    np.testing.assert_array_equal(arm.advance(2.0), np.zeros(m))


def test_noise_streams_are_seeded_and_independent(scene):
    """The tip noise of a seed is the same with or without pressure noise; both are seeded."""
    m = len(scene.actuator_names)
    order = np.arange(m)
    quiet = _arm(scene, order, tip_noise=2e-4)
    noisy = _arm(scene, order, tip_noise=2e-4, pressure_noise=500.0)
    pressure_stream = np.random.default_rng(np.random.SeedSequence(SEED, spawn_key=(1,)))
    tip_stream = np.random.default_rng(SEED)
    for arm in (quiet, noisy):
        arm.send(0.0, np.full(m, 1.0))
    for time in (0.01, 0.02):
        np.testing.assert_array_equal(quiet.advance(time), quiet.pressures)
        np.testing.assert_allclose(noisy.advance(time) - noisy.pressures,
                                   pressure_stream.normal(0.0, 500.0, m), rtol=0.0, atol=1e-9)
        result, quiet_tip = quiet.update_plant()
        _, noisy_tip = noisy.update_plant()
        np.testing.assert_array_equal(quiet_tip, noisy_tip)
        np.testing.assert_allclose(quiet_tip - result.effector_positions[-1],
                                   tip_stream.normal(0.0, 2e-4, 3), rtol=0.0, atol=1e-15)


def test_simulated_stereo_renders_each_plant_state_once():
    from cbha_inverse.sim.cameras import SimulatedStereo
    from cbha_inverse.vision.rig import load_rig
    stereo = SimulatedStereo(load_rig(config_path('cameras/demo_rig.yaml')), 0.006, SEED)
    tip = np.array([0.23, 0.0, -0.03])
    backbone = np.linspace([0.0, 0.0, 0.0], tip, 5)
    left, right = stereo.render(tip, backbone, time=1.0)
    assert left.shape == right.shape and left.dtype == np.uint8 and left.shape[2] == 3
    assert stereo.render(tip, backbone, time=1.0) is None       # that state was sent
    assert stereo.render(tip, backbone, time=1.01) is not None
