"""The shape estimator's section stiffness unknowns against the scaled scene's equilibria."""

from cbha_inverse.core.sections import link_sections, section_link_factors
from cbha_inverse.estimate.shape import EstimatorOptions, ShapeEstimator
from cbha_inverse.scene import load_scene
from cbha_inverse.scene.calibration import Calibration
import numpy as np
import pytest

SECTIONS = {'inner': 1.15, 'outer': 0.85}
GAINS = {'inner_over': 1.1, 'inner_right': 0.9, 'inner_left': 1.05, 'outer_over': 0.92,
         'outer_right': 1.08, 'outer_left': 0.95}
# within the bounds with a margin (the estimated actuation's offsets must stay inside them)
PRESSURES = np.array([1.2e5, 0.3e5, 0.2e5, 0.2e5, 0.9e5, 0.2e5])


@pytest.fixture(scope='module')
def cbha():
    return load_scene('cbha')


def _scaled(factors, **calibration):
    """Return the CBHA scene with its sections' stiffness scaled by ``factors`` (inner, outer)."""
    return load_scene('cbha', calibration=Calibration(
        section_stiffness=dict(zip(('inner', 'outer'), map(float, factors))), **calibration))


def test_the_sections_scale_the_links_the_scene_names(cbha):
    """Membership from the scene: links 0-7 inner, 8-15 outer; the calibration scales them."""
    assert cbha.section_links == {'inner': (0, 8), 'outer': (8, 8)}
    np.testing.assert_array_equal(link_sections(cbha.section_links, 16), [0] * 8 + [1] * 8)
    factors = section_link_factors(cbha.section_links, {'outer': 0.85}, 16)
    np.testing.assert_array_equal(factors, [1.0] * 8 + [0.85] * 8)
    nominal = cbha.model.stiffnesses
    np.testing.assert_allclose(_scaled((1.0, 0.85)).model.stiffnesses,
                               nominal * factors[:, None, None], rtol=1e-9,
                               atol=1e-12 * np.abs(nominal).max())


@pytest.mark.parametrize('pressures', [np.full(6, 2e4), PRESSURES], ids=['straight', 'bent'])
def test_the_estimate_is_the_scaled_chain_and_its_columns_are_the_derivative(cbha, pressures):
    """
    Held pose of a plant with section errors: the estimate is the scaled scene's equilibrium.

    The estimator's frames are the equilibrium of the scene whose sections carry the estimated
    factors (``calibration.section_stiffness``), at the estimated actuation: the factors scale
    the links in the linearisation itself. The pots' columns of the factors (``h`` over the
    scale) are the central differences of that scene's equilibria in each factor.
    """
    plant = _scaled((SECTIONS['inner'], SECTIONS['outer']))
    result = plant.forward(pressures, strict=True)
    lengths = plant.sensors.lengths(result.state.positions, result.state.rotations)
    estimator = ShapeEstimator.from_scene(cbha, EstimatorOptions(section_stiffness_std=0.2))
    for _ in range(30):
        estimate = estimator.update(cbha.sensors.readings(lengths), pressures)
    assert estimate.status == 'ok'
    factors = estimate.section_stiffness
    assert factors.shape == (2,) and np.abs(factors - 1.0).min() > 1e-3, factors
    data = estimator._data
    actuation = data.actuation.copy()
    here = _scaled(factors).forward(actuation, initial_state=estimator.state, strict=True)
    np.testing.assert_allclose(estimate.tip, here.effector_positions[-1], atol=1e-6)
    step = 1e-4
    for j in range(2):
        lengths_at = []
        for sign in (1.0, -1.0):
            moved = factors.copy()
            moved[j] += sign * step
            other = _scaled(moved).forward(actuation, initial_state=here.state, strict=True)
            lengths_at.append(cbha.sensors.lengths(other.state.positions,
                                                   other.state.rotations))
        derivative = (lengths_at[0] - lengths_at[1]) / (2.0 * step)
        column = data.h[:, 12 + j] / data.unknown_scale[12 + j]
        assert np.abs(derivative).max() > 1e-3  # a section's stiffness moves its pots
        np.testing.assert_allclose(column, derivative, rtol=0.01,
                                   atol=0.003 * np.abs(derivative).max())


def _lap(options, calibration, payload=0.0, laps=3, lap=200):
    """Laps of pressures on a plant with ``calibration``; the last lap's tip errors, estimate."""
    estimator = ShapeEstimator.from_scene(load_scene('cbha'), options)
    plant = _scaled((SECTIONS['inner'], SECTIONS['outer']), tip_payload_mass=payload,
                    **calibration)
    rng = np.random.default_rng(3)
    state, errors = None, []
    for k in range(laps * lap):
        pressures = 6e4 + 4e4 * np.cos(2.0 * np.pi * k / lap + np.arange(6) * np.pi / 3.0)
        result = plant.forward(pressures, initial_state=state, strict=True)
        state = result.state
        lengths = plant.sensors.lengths(state.positions, state.rotations)
        estimate = estimator.update(
            estimator.sensors.readings(lengths + 1e-4 * rng.standard_normal(6)), pressures)
        if k >= (laps - 1) * lap:
            errors.append(estimate.tip - result.effector_positions[-1])
    return np.sqrt(np.mean(np.sum(np.square(errors), axis=1))), estimate


def test_the_sections_stiffness_is_found_where_the_cavity_gains_are_known():
    """
    Plant sections x1.15 / x0.85, cavity gains right (their prior tight), 0.1 mm pot noise.

    The factors converge to the plant's and the tip error drops (0.11 against 0.19 mm): a
    section's stiffness and the gains of its three cavities bend it alike, what tells them
    apart is the sag under the arm's weight.
    """
    options = {'gain_std': 1e-3}
    without, _ = _lap(EstimatorOptions(**options), {})
    with_sections, estimate = _lap(EstimatorOptions(section_stiffness_std=0.2, **options), {})
    np.testing.assert_allclose(estimate.section_stiffness, [1.15, 0.85], atol=0.01)
    assert with_sections < 0.7 * without, (with_sections, without)


def test_with_cavity_gain_errors_too_the_tip_improves():
    """
    Gains +-10 % off as well (free in the filter): the factors trade against the gains.

    Each section's stiffness and its cavities' common gain bend it alike, so the factors are
    not the plant's (1.06 / 1.15 here), but the tip error drops (0.13 against 0.19 mm).
    """
    calibration = {'actuator_gain': GAINS}
    without, _ = _lap(EstimatorOptions(), calibration)
    with_sections, estimate = _lap(EstimatorOptions(section_stiffness_std=0.2), calibration)
    assert with_sections < 0.8 * without and with_sections < 1.6e-4, (with_sections, without)
    assert np.all(np.abs(estimate.section_stiffness - 1.0) < 0.3)


def test_the_factors_stay_within_their_bounds(cbha):
    """A factor driven toward zero (or far up) is held within 0.5-2: the chain stays stiff."""
    state = cbha.forward(PRESSURES, strict=True).state
    lengths = cbha.sensors.lengths(state.positions, state.rotations)
    estimator = ShapeEstimator.from_scene(cbha, EstimatorOptions(section_stiffness_std=0.2))
    estimator.update(cbha.sensors.readings(lengths), PRESSURES)
    data = estimator._data
    data.masses[-2:] = [-0.95, 4.0]
    data.z[-2:] = data.masses[-2:] / data.unknown_scale[-2:]
    estimate = estimator.update(cbha.sensors.readings(lengths), PRESSURES)
    assert np.all(np.isfinite(estimate.tip)), estimate
    np.testing.assert_allclose(estimate.section_stiffness, [0.5, 2.0])


def test_the_unknown_needs_the_scene_sections(cbha):
    with pytest.raises(ValueError, match='sections'):
        ShapeEstimator(cbha.model, cbha.actuators, cbha.effectors, cbha.sensors,
                       gravity=cbha.gravity,
                       options=EstimatorOptions(section_stiffness_std=0.2))
