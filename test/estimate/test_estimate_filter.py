"""The shape estimator's Kalman update and buffers against independent references."""

from cbha_inverse.core._kernels import estimation as kernel
from cbha_inverse.estimate.shape import EstimatorOptions, ShapeEstimator
from cbha_inverse.scene import load_scene
from cbha_inverse.scene.calibration import Calibration
import numba
import numpy as np
import pytest

PRESSURES = np.array([1.2e5, 0.3e5, 0.0, 0.2e5, 0.9e5, 0.0])


@pytest.fixture(scope='module')
def cbha():
    return load_scene('cbha')


def test_the_sequential_update_is_the_batch_information_form():
    """The pots one after the other equal the batch posterior of all (linear Gaussian)."""
    rng = np.random.default_rng(0)
    c, u = 6, 13
    h = rng.standard_normal((c, u)) * 1e-3
    measured = rng.standard_normal(c) * 1e-3
    noise = 1e-4 * (1.0 + rng.random(c))
    base = rng.standard_normal(c) * 1e-4
    z = rng.standard_normal(u)
    walk = 0.01 * rng.random(u)
    root = rng.standard_normal((u, u))
    covariance = root @ root.T + np.eye(u)
    stuck = np.zeros(c, dtype=bool)
    stuck[2] = True
    prior_mean = z.copy()
    prior = covariance + np.diag(walk)
    active = np.zeros(c, dtype=bool)
    ratio, predicted = np.zeros(c), np.zeros(c)
    kernel.kalman_lengths(h, measured, noise, base, z, walk, covariance, stuck, 0.0, active,
                          np.zeros(u), ratio, predicted)
    assert active.tolist() == [True, True, False, True, True, True]
    used = h[active]
    weights = np.diag(1.0 / noise[active] ** 2)
    information = np.linalg.inv(prior) + used.T @ weights @ used
    posterior = np.linalg.inv(information)
    mean = posterior @ (np.linalg.solve(prior, prior_mean) + used.T @ weights @ (
        measured[active] - base[active]))
    np.testing.assert_allclose(z, mean, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(covariance, posterior, rtol=1e-7, atol=1e-12)
    np.testing.assert_allclose(predicted, base + h @ mean)
    spread = np.sqrt(noise ** 2 + np.einsum('ij,jk,ik->i', h, prior, h))
    innovation = measured - base - h @ prior_mean
    np.testing.assert_allclose(ratio, np.abs(innovation) / spread)


@numba.njit
def _estimator_fields(estimator):
    """Return the arrays the compiled update reads through its record's tick and system."""
    tick = estimator.tick
    return (tick.system.external, tick.solved, tick.system.rhs, tick.effector_columns,
            tick.effector_frames, tick.system.blocks, tick.positions, tick.actuation,
            tick.system.stiffness)


def test_the_buffers_are_the_tick_data_and_the_system(cbha):
    """The compiled entry reads the tick data's own arrays (the same objects, not copies)."""
    estimator = ShapeEstimator.from_scene(cbha, EstimatorOptions(payload_std=0.1))
    data = estimator._data
    system = estimator._system
    (external, solved, rhs, effector_columns, frames, blocks, positions, actuation,
     stiffness) = _estimator_fields(data.record)
    assert external is data.external
    assert external is system.external
    assert external is system.record.external
    assert solved is data.tick.solved
    assert rhs is system.record.rhs
    assert effector_columns is data.tick.effector_columns
    assert blocks is system.record.blocks
    assert positions is data.positions
    assert actuation is data.actuation
    np.testing.assert_array_equal(frames, cbha.effectors.frames)
    # the base of the external wrenches is the system's own, a copy (the update adds the
    # weights' wrenches to the system's)
    np.testing.assert_array_equal(data.base_external, system.external)
    assert not np.shares_memory(data.base_external, system.external)
    # the tick evaluates the model's stiffness (read-only for the compiled code)
    np.testing.assert_array_equal(stiffness, np.asarray(cbha.model.stiffnesses))
    assert not stiffness.flags.writeable
    # a write from Python is seen by the compiled code: the same memory
    data.positions[-1, 0] += 1.0
    assert _estimator_fields(data.record)[6][-1, 0] == data.positions[-1, 0]


def test_the_filter_averages_the_pot_noise_at_a_held_pose(cbha):
    """Held pose, 0.1 mm pot noise: the tip is far better than one sample's (~10x the noise)."""
    result = cbha.forward(PRESSURES, strict=True)
    tip = result.effector_positions[-1]
    lengths = cbha.sensors.lengths(result.state.positions, result.state.rotations)
    rng = np.random.default_rng(3)
    estimator = ShapeEstimator.from_scene(cbha)
    single = ShapeEstimator.from_scene(cbha, EstimatorOptions(outlier_sigma=1e9))
    errors, singles = [], []
    for _ in range(300):
        readings = cbha.sensors.readings(lengths + 1e-4 * rng.standard_normal(6))
        estimate = estimator.update(readings, PRESSURES)
        errors.append(np.linalg.norm(estimate.tip - tip))
        # the reference: the same readings, each from the prior of the first update
        single.reset()
        singles.append(np.linalg.norm(single.update(readings, PRESSURES).tip - tip))
    late = np.sqrt(np.mean(np.square(errors[200:])))
    one_sample = np.sqrt(np.mean(np.square(singles[200:])))
    assert estimate.status == 'ok'
    assert one_sample > 3e-4 and late < 0.1 * one_sample, (late, one_sample)
    # the reported spread follows the averaging
    assert estimate.confidence < 0.2 * one_sample


@pytest.mark.parametrize('pressures', [np.zeros(6), PRESSURES], ids=['rest', 'bent'])
def test_the_compiled_payload_column_is_the_lengths_derivative_in_the_mass(cbha, pressures):
    """The pots' row of the payload (``h``'s last column) against a difference of equilibria."""
    result = cbha.forward(pressures, strict=True)
    lengths = cbha.sensors.lengths(result.state.positions, result.state.rotations)
    estimator = ShapeEstimator.from_scene(cbha, EstimatorOptions(payload_std=0.1))
    for _ in range(5):
        estimator.update(cbha.sensors.readings(lengths), pressures)
    data, step = estimator._data, 1e-3
    loaded = load_scene('cbha', calibration=Calibration(tip_payload_mass=step)).forward(
        pressures, initial_state=result.state, strict=True)
    derivative = (cbha.sensors.lengths(loaded.state.positions, loaded.state.rotations)
                  - lengths) / step
    assert np.abs(derivative).max() > 1e-3  # a tip weight stretches and bends the pots
    np.testing.assert_allclose(data.h[:, -1] / data.unknown_scale[-1], derivative,
                               rtol=0.05, atol=0.02 * np.abs(derivative).max())


def test_a_held_tip_payload_is_estimated_not_left_to_the_offsets(cbha):
    """At rest with 0.1 kg at the plant's tip the payload takes a share of the sag."""
    plant = load_scene('cbha', calibration=Calibration(tip_payload_mass=0.1))
    result = plant.forward(np.zeros(6), strict=True)
    lengths = plant.sensors.lengths(result.state.positions, result.state.rotations)
    estimator = ShapeEstimator.from_scene(cbha, EstimatorOptions(payload_std=0.1))
    for _ in range(20):
        estimate = estimator.update(cbha.sensors.readings(lengths), np.zeros(6))
    # (the offsets explain the rest: at one pose a tip weight bends the arm much as they do)
    assert 0.02 < estimate.payload < 0.15, estimate.payload
    np.testing.assert_allclose(estimate.tip, result.effector_positions[-1], atol=5e-3)
