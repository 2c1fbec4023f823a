"""cbha_identify on bags with string pots: their offsets and gains, a wrong pot order refused."""

import json

from cbha_inverse.identify.cli import main
from cbha_inverse.identify.fit import parameter_names, TipPredictor
from cbha_inverse.identify.pots import calibrate_pots
from cbha_inverse.identify.samples import (IdentificationError, pooled_samples,
                                           quasi_static_samples, read_session)
from cbha_inverse.scene import load_scene
import numpy as np
import pytest
from session_bags import write_session_bag

TRUTH = np.array([0.85, 1.1, 0.9, 1.05, 1.1, 0.95, 1.08, 0.92])
TIP_NOISE = 2e-4
POT_NOISE = 1e-4
OFFSETS = np.array([3.0, -2.0, 1.5, -4.0, 2.5, -1.0])           # readings (mm)
GAINS = np.array([1030.0, 970.0, 1020.0, 985.0, 1040.0, 960.0])  # readings per m


@pytest.fixture(scope='module')
def cbha():
    return load_scene('cbha')


@pytest.fixture(scope='module')
def plant(cbha):
    """Commands held 0.5 s each, the plant's tips and the routed lengths of its pots."""
    commands = np.random.default_rng(5).uniform(0.0, 150e3, (16, 6))
    predict = TipPredictor('cbha', parameter_names(cbha), commands, sensor_lengths=True)
    tips = predict(TRUTH)
    return commands, tips, predict.lengths.copy()


def _write(path, cbha, plant, names=None, seed=0):
    """Write the plant's session: 25 tips at 50 Hz and 50 pot readings at 100 Hz per hold."""
    commands, tips, lengths = plant
    rng = np.random.default_rng(seed)
    times = 1.0 + 0.5 * np.arange(len(commands))
    tip_times = times[:, None] + 0.02 * np.arange(25)
    pot_times = times[:, None] + 0.005 + 0.01 * np.arange(50)
    noisy_tips = tips[:, None] + rng.normal(0.0, TIP_NOISE, (len(tips), 25, 3))
    noisy = lengths[:, None] + rng.normal(0.0, POT_NOISE, (len(tips), 50, 6))
    readings = OFFSETS + GAINS * noisy
    names = cbha.sensors.names if names is None else names
    write_session_bag(
        path, commands=list(zip(times, commands)),
        tips=list(zip(tip_times.reshape(-1), noisy_tips.reshape(-1, 3))),
        pots=[(t, names, r) for t, r in zip(pot_times.reshape(-1), readings.reshape(-1, 6))])


def test_cbha_identify_recovers_the_pot_calibration_within_its_standard_errors(
        tmp_path, cbha, plant):
    _write(tmp_path / 'bag', cbha, plant)
    assert main([str(tmp_path / 'bag'), '--output', str(tmp_path / 'out'), '--quiet',
                 '--max-samples', '32']) == 0
    result = json.loads((tmp_path / 'out' / 'cbha_identified.json').read_text())
    pots = result['string_pots']
    assert pots['warnings'] == [] and pots['samples'] == 32
    for name, offset, gain in zip(cbha.sensors.names, OFFSETS, GAINS):
        fit = pots['pots'][name]
        assert fit['gain_fitted']
        assert abs(fit['gain'] - gain) <= 3.0 * fit['gain_standard_error'], (name, fit)
        assert abs(fit['offset'] - offset) <= 3.0 * fit['offset_standard_error'], (name, fit)
        assert fit['gain_standard_error'] < 0.01 * gain
        assert fit['residual_m'] < 2.0 * POT_NOISE
    report = (tmp_path / 'out' / 'cbha_identified_report.txt').read_text()
    assert 'string pots (reading = offset + gain' in report
    # the written scene reads the plant's pots: lengths of a new pose from its readings
    identified = load_scene(tmp_path / 'out' / 'cbha_identified.yaml')
    probe = np.array([[120e3, 10e3, 60e3, 30e3, 140e3, 0.0]])
    predict = TipPredictor('cbha', parameter_names(cbha), probe, sensor_lengths=True)
    predict(TRUTH)
    true_lengths = predict.lengths[0]
    readings = OFFSETS + GAINS * true_lengths
    assert np.max(np.abs(identified.sensors.lengths_of(readings) - true_lengths)) < 2e-4
    assert np.max(np.abs(cbha.sensors.lengths_of(readings) - true_lengths)) > 5e-3


@pytest.mark.parametrize('swap', [(0, 1), (3, 5), (1, 4)])
def test_a_swapped_pot_order_is_refused(cbha, plant, swap):
    """Two pots' readings exchanged (by the driver's names or the scene's block) are named."""
    commands, _, lengths = plant
    readings = OFFSETS + GAINS * (lengths + np.random.default_rng(3).normal(0.0, POT_NOISE,
                                                                            lengths.shape))
    names = list(cbha.sensors.names)
    a, b = (names[k] for k in swap)
    names[swap[0]], names[swap[1]] = b, a
    with pytest.raises(IdentificationError, match='the pot order is wrong') as error:
        calibrate_pots('cbha', parameter_names(cbha), TRUTH, np.zeros((8, 8)), commands,
                       readings, names)
    assert f'{a} follows the length of {b}' in str(error.value)
    assert f'{b} follows the length of {a}' in str(error.value)
    # in the right order the same readings calibrate
    calibrate_pots('cbha', parameter_names(cbha), TRUTH, np.zeros((8, 8)), commands, readings,
                   cbha.sensors.names)


def test_a_recording_without_a_scene_pot_is_refused(tmp_path, cbha, plant, capsys):
    names = list(cbha.sensors.names)
    names[2] = 'string_pot_spare'
    _write(tmp_path / 'bag', cbha, plant, names=names)
    assert main([str(tmp_path / 'bag'), '--output', str(tmp_path / 'out'), '--quiet',
                 '--max-samples', '32']) == 1
    assert "lack the scene pots ['string_pot_inner_left']" in capsys.readouterr().err


def test_pots_the_samples_do_not_move_keep_their_gain(cbha, plant):
    """Poses too close together: the gains stay the scene's, the offsets match the readings."""
    commands, _, _ = plant
    held = commands[0] + np.random.default_rng(2).uniform(-1e3, 1e3, (12, 6))
    predict = TipPredictor('cbha', parameter_names(cbha), held, sensor_lengths=True)
    predict(TRUTH)
    readings = OFFSETS + GAINS * predict.lengths
    fit = calibrate_pots('cbha', parameter_names(cbha), TRUTH, np.zeros((8, 8)), held,
                         readings, cbha.sensors.names)
    assert not fit.gain_fitted.any()
    np.testing.assert_array_equal(fit.gains, cbha.sensors.reading_gain)
    assert np.all(fit.gain_errors == 0.0)
    assert len(fit.warnings) == 6 and all('gain kept at the scene' in w for w in fit.warnings)
    # the kept gain with the fitted offset reproduces the readings at the held pose
    mean = predict.lengths.mean(axis=0)
    np.testing.assert_allclose(fit.offsets + fit.gains * mean, OFFSETS + GAINS * mean,
                               atol=1e-6)


def test_pot_standard_errors_match_the_scatter_of_repeated_fits(cbha, plant):
    """Over noise draws, (fitted - truth) / standard error of the gains is N(0, 1)."""
    commands, _, lengths = plant
    rng = np.random.default_rng(11)
    z = []
    for _ in range(8):
        readings = OFFSETS + GAINS * (lengths + rng.normal(0.0, POT_NOISE, lengths.shape))
        fit = calibrate_pots('cbha', parameter_names(cbha), TRUTH, np.zeros((8, 8)), commands,
                             readings, cbha.sensors.names)
        z += list((fit.gains - GAINS) / fit.gain_errors)
    assert 0.6 < np.sqrt(np.mean(np.square(z))) < 1.5


def test_the_model_uncertainty_widens_the_pot_standard_errors(cbha, plant):
    commands, _, lengths = plant
    readings = OFFSETS + GAINS * lengths
    names = parameter_names(cbha)
    exact = calibrate_pots('cbha', names, TRUTH, np.zeros((8, 8)), commands, readings,
                           cbha.sensors.names)
    uncertain = calibrate_pots('cbha', names, TRUTH, np.diag((0.01 * TRUTH) ** 2), commands,
                               readings, cbha.sensors.names)
    assert np.all(uncertain.gain_errors > 10.0 * exact.gain_errors)
    with pytest.raises(IdentificationError, match='declares no sensors'):
        calibrate_pots('tendon_6f_8c', ('actuator_gain.c0',), [1.0], np.zeros((1, 1)),
                       np.zeros((3, 8)), readings[:3], cbha.sensors.names)


def test_pot_readings_are_read_by_name_interpolated_and_bad_ones_dropped(tmp_path):
    names = ('a', 'b')
    pots = [(1.0 + 0.01 * k, names, [k, 2.0 * k]) for k in range(100)]
    pots[10] = (pots[10][0], ('b', 'a'), [0.0, 0.0])        # other names
    pots[20] = (pots[20][0], names, [np.nan, 1.0])           # not finite
    pots[30] = (pots[30][0], names, [1.0])                   # too short
    tips = [(1.5 + 0.01 * k, [0.2, 0.0, 0.0]) for k in range(40)]
    write_session_bag(tmp_path / 'bag', commands=[(1.0, np.zeros(6))], tips=tips, pots=pots)
    session = read_session(tmp_path / 'bag')
    assert session.pot_names == names and session.pots_dropped == 3
    assert len(session.pot_times) == 97
    samples = quasi_static_samples(session, max_samples=1000)
    # the readings are linear in time: interpolated exactly at the tips' receive times
    expected = (samples.receive_times - 1.0) / 0.01
    np.testing.assert_allclose(samples.pots, np.stack([expected, 2.0 * expected], axis=1),
                               atol=1e-6)
    write_session_bag(tmp_path / 'bare', commands=[(1.0, np.zeros(6))], tips=tips)
    bare = quasi_static_samples(read_session(tmp_path / 'bare'), max_samples=1000)
    pooled = pooled_samples([samples, bare], 1000)
    assert pooled.pot_names == names
    assert np.isfinite(pooled.pots[pooled.part == 0]).all()
    assert np.isnan(pooled.pots[pooled.part == 1]).all()
    other = samples.__class__(**{**samples.__dict__, 'pot_names': ('a', 'c')})
    with pytest.raises(IdentificationError, match='name different string pots'):
        pooled_samples([samples, other], 1000)


def test_the_tip_reference_of_a_simulation_is_tip_true(tmp_path):
    tips = [(1.5 + 0.01 * k, [0.2, 0.0, 0.01 * k]) for k in range(10)]
    write_session_bag(tmp_path / 'bag', commands=[(1.0, np.zeros(6))], tips=tips,
                      tip_topic='tip/true')
    with pytest.raises(IdentificationError, match='no /cbha/tip/measured messages'):
        read_session(tmp_path / 'bag')
    session = read_session(tmp_path / 'bag', tip='tip/true')
    np.testing.assert_allclose(session.tips, [tip for _, tip in tips])
