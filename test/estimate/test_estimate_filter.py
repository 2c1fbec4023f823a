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
    pots = np.zeros((kernel.POT_ROWS, c))
    pots[kernel.MEASURED] = rng.standard_normal(c) * 1e-3
    pots[kernel.NOISE] = 1e-4 * (1.0 + rng.random(c))
    pots[kernel.BASE] = rng.standard_normal(c) * 1e-4
    state = np.zeros((kernel.STATE_ROWS, u))
    state[kernel.Z] = rng.standard_normal(u)
    state[kernel.WALK] = 0.01 * rng.random(u)
    root = rng.standard_normal((u, u))
    covariance = root @ root.T + np.eye(u)
    stuck = np.zeros(c, dtype=bool)
    stuck[2] = True
    prior_mean = state[kernel.Z].copy()
    prior = covariance + np.diag(state[kernel.WALK])
    active = np.zeros(c, dtype=bool)
    work = np.zeros(u + 2)
    kernel.kalman_lengths(h, pots, state, covariance, stuck, active, work)
    assert active.tolist() == [True, True, False, True, True, True]
    used = h[active]
    weights = np.diag(1.0 / pots[kernel.NOISE, active] ** 2)
    information = np.linalg.inv(prior) + used.T @ weights @ used
    posterior = np.linalg.inv(information)
    mean = posterior @ (np.linalg.solve(prior, prior_mean) + used.T @ weights @ (
        pots[kernel.MEASURED, active] - pots[kernel.BASE, active]))
    np.testing.assert_allclose(state[kernel.Z], mean, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(covariance, posterior, rtol=1e-7, atol=1e-12)
    np.testing.assert_allclose(pots[kernel.PREDICTED], pots[kernel.BASE] + h @ mean)
    spread = np.sqrt(pots[kernel.NOISE] ** 2 + np.einsum('ij,jk,ik->i', h, prior, h))
    innovation = pots[kernel.MEASURED] - pots[kernel.BASE] - h @ prior_mean
    np.testing.assert_allclose(pots[kernel.RATIO], np.abs(innovation) / spread)


@numba.njit
def _estimator_fields(buffers):
    """Return the fields of the tick's buffers the compiled update reads beside the tick's."""
    return (buffers.external, buffers.solved, buffers.rhs, buffers.effector_matrices,
            buffers.effector_frames, buffers.band)


def test_the_buffers_are_the_tick_data_and_the_system(cbha):
    """The compiled entry reads the tick data's own arrays (the same objects, not copies)."""
    estimator = ShapeEstimator.from_scene(cbha, EstimatorOptions(payload_std=0.1))
    data = estimator._data
    assert data.arguments[0] is data.tick.buffers
    external, solved, rhs, effector_matrices, frames, band = _estimator_fields(
        data.tick.buffers)
    assert external is data.external
    np.testing.assert_array_equal(data.external, estimator._system.external)
    assert solved is data.tick.solved
    assert rhs is data.tick.rhs
    assert effector_matrices is data.tick.effector_matrices
    assert band is data.tick.band
    np.testing.assert_array_equal(frames, cbha.effectors.frames)


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
    np.testing.assert_allclose(data.h[:, -1] / data.state[kernel.SCALE, -1], derivative,
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
