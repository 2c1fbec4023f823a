"""cbha_identify: recovery of known plant errors, clear refusals of data that cannot give a fit."""

import io
import json
import re
import time

from cbha_inverse.identify.cli import main
from cbha_inverse.identify.fit import identify, parameter_names, TipPredictor
from cbha_inverse.identify.progress import ProgressLine
from cbha_inverse.identify.samples import (IdentificationError, quasi_static_samples,
                                           valve_pressures)
from cbha_inverse.metrics import cross_track_errors
from cbha_inverse.scene import load_scene, resolve_scene_path
import numpy as np
import pytest
from session_bags import write_session_bag
import yaml

TRUTH = np.array([0.85, 1.1, 0.9, 1.05, 1.1, 0.95, 1.08, 0.92])
NOISE = 2e-4


@pytest.fixture(scope='module')
def synthetic():
    """Pressures spread over the box and the tips of a plant with known errors (+ noise)."""
    rng = np.random.default_rng(3)
    pressures = rng.uniform(0.0, 150e3, (24, 6))
    names = parameter_names(load_scene('cbha'))
    tips = TipPredictor('cbha', names, pressures)(TRUTH)
    return pressures, tips + rng.normal(0.0, NOISE, tips.shape)


def test_fit_recovers_known_errors_within_their_standard_errors(synthetic):
    pressures, tips = synthetic
    result = identify('cbha', pressures, tips, max_relative_error=1.0, max_correlation=1.0)
    assert result.names[:2] == ('section_stiffness.inner', 'section_stiffness.outer')
    assert np.all(np.abs(result.values - TRUTH) <= 3.0 * result.standard_errors)
    assert result.rms_before > 10e-3
    # the fitted model explains the data down to the noise (norm of 3 axes of NOISE)
    assert result.rms_after < 1.5 * np.sqrt(3.0) * NOISE
    np.testing.assert_allclose(np.diag(result.correlation), 1.0)
    assert result.warnings == ()
    assert result.calibration.section_stiffness['inner'] == pytest.approx(result.values[0])


@pytest.fixture(scope='module')
def short_arm(tmp_path_factory):
    """Return the CBHA scene with 3 segments per section, its sample pressures and tips."""
    # the outer section's weight is too small to separate its stiffness from its gains (its
    # absolute scale is unseen), and fits are fast
    source = resolve_scene_path('cbha')
    data = yaml.safe_load(source.read_text())
    for section in data['chain']['sections']:
        section['segment'] = str((source.parent / section['segment']).resolve())
        section['count'] = 3
    # its string pots are routed to vertebrae 8 and 16 of the full arm
    data.pop('sensors', None)
    path = tmp_path_factory.mktemp('scene') / 'short_arm.yaml'
    path.write_text(yaml.safe_dump(data))
    rng = np.random.default_rng(7)
    pressures = rng.uniform(0.0, 150e3, (16, 6))
    tips = TipPredictor(path, parameter_names(load_scene(path)), pressures)(TRUTH)
    return path, pressures, tips


def test_what_the_data_cannot_see_stays_at_the_prior_and_is_flagged(short_arm):
    path, pressures, clean = short_arm
    tips = clean + np.random.default_rng(8).normal(0.0, NOISE, clean.shape)
    free = identify(path, pressures, tips, prior_sigma=None)
    fit = identify(path, pressures, tips, prior_sigma=0.5)
    error = np.log(fit.values / TRUTH) / (fit.standard_errors / fit.values)
    assert np.all(np.abs(error) < 2.0)
    # without the prior the unseen direction drifts far from the truth (factor > 2)
    assert np.max(np.abs(np.log(free.values / TRUTH))) > np.log(2.0)
    # the least determined combination: the outer stiffness and gains together, mostly prior
    weakest = fit.directions[:, 0]
    assert fit.data_share[0] < 0.5
    assert np.all(np.abs(np.abs(weakest[[1, 5, 6, 7]]) - 0.5) < 0.05)
    assert any('set mostly by the prior' in w and 'section_stiffness.outer' in w
               for w in fit.warnings)
    # both fits explain the data alike: only the prior tells them apart
    assert fit.rms_after == pytest.approx(free.rms_after, rel=0.05)


def test_reported_standard_errors_match_the_scatter_of_repeated_fits(short_arm):
    # Monte Carlo: along each combination the data determines, the fitted error over the
    # reported standard error is N(0, 1) over noise draws (too small or too large SEs fail)
    path, pressures, clean = short_arm
    rng = np.random.default_rng(9)
    z = []
    for _ in range(6):
        fit = identify(path, pressures, clean + rng.normal(0.0, NOISE, clean.shape))
        relative = fit.standard_errors / fit.values
        covariance = fit.correlation * np.outer(relative, relative)
        for direction, share in zip(fit.directions.T, fit.data_share):
            if share > 0.95:
                z.append(direction @ np.log(fit.values / TRUTH)
                         / np.sqrt(direction @ covariance @ direction))
    z = np.array(z)
    assert len(z) >= 30
    assert 0.7 < np.sqrt(np.mean(z ** 2)) < 1.4


def test_bad_shapes_and_values_are_refused_at_the_door(synthetic):
    pressures, tips = synthetic
    with pytest.raises(ValueError, match=r'tips must be a finite \(N, 3\)'):
        identify('cbha', pressures, tips[:, :2])
    with pytest.raises(ValueError, match=r'tips must be a finite'):
        identify('cbha', pressures, np.where(tips > 0.1, np.nan, tips))
    with pytest.raises(ValueError, match=r'pressures must be a finite \(24, 6\) array'):
        identify('cbha', pressures[:, :5], tips)
    with pytest.raises(ValueError, match=r'pressures must be a finite \(24, 6\) array'):
        identify('cbha', pressures[:20], tips)
    with pytest.raises(ValueError, match='prior_sigma must be finite and > 0'):
        identify('cbha', pressures, tips, prior_sigma=0.0)
    with pytest.raises(ValueError, match='needs the pressures as a function'):
        identify('cbha', pressures, tips, latency=0.003)


def test_valve_pressures_follow_delayed_first_order_lag():
    times = np.array([0.0, 1.0])
    commands = np.array([[100.0], [0.0]])
    at = np.array([-0.5, 0.0, 0.003, 0.013, 1.003, 1.013])
    out = valve_pressures(times, commands, at, 0.003, 0.01)[:, 0]
    after_first = 100.0 * (1.0 - np.exp(-1.0 / 0.01))
    np.testing.assert_allclose(out, [0.0, 0.0, 0.0, 100.0 * (1.0 - np.exp(-1.0)), after_first,
                                     after_first * np.exp(-1.0)], atol=1e-9)


def _write_session(path, command_times, commands, tip_times=(), tips=()):
    """Write ``pressure_command`` and ``tip/measured`` messages at their times [s] to a bag."""
    write_session_bag(path, list(zip(command_times, commands)), tips=list(zip(tip_times, tips)))


def _write_bag(path, commands, tips=None, noise=0.0):
    """Write a session: a command every 0.5 s, then 25 tips at 50 Hz (``tips[k]`` + noise)."""
    command_times = 1.0 + 0.5 * np.arange(len(commands))
    if tips is None:
        return _write_session(path, command_times, commands)
    tip_times = (command_times[:, None] + 0.02 * np.arange(25)).reshape(-1)
    measured = np.repeat(tips, 25, axis=0)
    measured = measured + np.random.default_rng(0).normal(0.0, noise, measured.shape)
    return _write_session(path, command_times, commands, tip_times, measured)


def test_cbha_identify_writes_a_scene_that_reproduces_the_plant(tmp_path, capsys):
    rng = np.random.default_rng(5)
    commands = rng.uniform(0.0, 150e3, (12, 6))
    names = parameter_names(load_scene('cbha'))
    tips = TipPredictor('cbha', names, commands)(TRUTH)
    _write_bag(tmp_path / 'bag', commands, tips, NOISE)
    started = time.monotonic()
    assert main([str(tmp_path / 'bag'), '--output', str(tmp_path / 'out'),
                 '--max-samples', '24']) == 0
    elapsed = time.monotonic() - started
    out = capsys.readouterr().out
    # progress off a terminal: the first evaluation, then at most one line per 5 s, the last
    shown = [line for line in out.splitlines() if ': tip RMS' in line]
    evaluations = int(re.search(r'(\d+) forward evaluations', out).group(1))
    assert shown[0].startswith('evaluation 1: ')
    numbers = [int(line.split()[1].rstrip(':')) for line in shown]
    assert numbers == sorted(numbers) and len(numbers) >= 2    # the last one ends the fit
    assert len(shown) <= 2 + elapsed / 5.0 < evaluations, out
    # --quiet: test_cbha_identify_verbose_prints_every_evaluation_and_quiet_none
    assert 'standard error' in (tmp_path / 'out' / 'cbha_identified_report.txt').read_text()
    assert (tmp_path / 'out' / 'cbha_identified.png').stat().st_size > 10_000
    identified = load_scene(tmp_path / 'out' / 'cbha_identified.yaml')
    probe = np.array([120e3, 10e3, 60e3, 30e3, 140e3, 0.0])
    plant = TipPredictor('cbha', names, probe[None])(TRUTH)[0]
    nominal = load_scene('cbha').forward(probe).effector_positions[-1]
    predicted = identified.forward(probe).effector_positions[-1]
    assert np.linalg.norm(nominal - plant) > 10e-3
    assert np.linalg.norm(predicted - plant) < 1e-3


def test_samples_of_several_bags_are_pooled_into_one_fit(tmp_path, capsys):
    rng = np.random.default_rng(6)
    commands = rng.uniform(0.0, 150e3, (12, 6))
    names = parameter_names(load_scene('cbha'))
    _write_bag(tmp_path / 'lap', commands, TipPredictor('cbha', names, commands)(TRUTH), NOISE)
    held = np.full((4, 6), 50e3)
    _write_bag(tmp_path / 'hold', held, TipPredictor('cbha', names, held)(TRUTH), NOISE)
    # the held pose alone cannot give a fit; with the lap it adds its samples
    assert main([str(tmp_path / 'hold'), '--output', str(tmp_path / 'alone')]) == 1
    assert 'too little excitation' in capsys.readouterr().err
    assert main([str(tmp_path / 'lap'), str(tmp_path / 'hold'), '--output',
                 str(tmp_path / 'out'), '--max-samples', '40']) == 0
    result = json.loads((tmp_path / 'out' / 'cbha_identified.json').read_text())
    counts = [int(line.split(' quasi-static')[0].split()[-1])
              for line in capsys.readouterr().out.splitlines() if 'quasi-static (' in line]
    assert len(counts) == 2 and min(counts) > 0
    assert result['samples']['quasi_static'] == sum(counts)
    assert result['samples']['fitted'] == 40
    assert result['samples']['recorded'] == (12 + 4) * 25
    for name, truth in zip(names, TRUTH):
        fitted = result['parameters'][name]
        assert abs(fitted['value'] - truth) <= 3.0 * fitted['standard_error']


def test_bag_without_tip_measurements_is_refused(tmp_path, capsys):
    _write_bag(tmp_path / 'bag', np.zeros((3, 6)))
    assert main([str(tmp_path / 'bag'), '--output', str(tmp_path / 'out')]) == 1
    err = capsys.readouterr().err
    assert 'no /cbha/tip/measured messages' in err
    assert not (tmp_path / 'out').exists()


def test_too_little_excitation_is_refused_not_presented_as_a_fit(tmp_path, capsys):
    _write_bag(tmp_path / 'bag', np.full((20, 6), 50e3), np.full((20, 3), [0.2, 0.0, -0.1]))
    assert main([str(tmp_path / 'bag'), '--output', str(tmp_path / 'out')]) == 1
    err = capsys.readouterr().err
    assert 'too little excitation' in err
    assert not (tmp_path / 'out').exists()


def test_quasi_static_selection_drops_samples_while_valves_move():
    times = np.array([0.0, 1.0])
    commands = np.array([[0.0], [100e3]])
    tip_times = np.linspace(0.01, 1.99, 100)
    session = (times, commands, tip_times, np.zeros((100, 3)))
    samples = quasi_static_samples(session, max_samples=1000)
    # after the step at 1.003 s the valve moves more than 2 kPa within 50 ms for ~0.09 s
    moving = (tip_times > 1.003) & (tip_times < 1.003 + 0.05 + 0.01 * np.log(100e3 / 2000.0))
    assert samples.quasi_static == 100 - moving.sum()
    during_step = np.linspace(1.01, 1.04, 5)
    with pytest.raises(IdentificationError, match='no quasi-static'):
        quasi_static_samples((times, commands, during_step, np.zeros((5, 3))))


def test_cross_track_error_is_the_distance_to_the_path_not_to_the_timed_target():
    square = np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0],
                       [0.0, 0.0, 0.0]])
    tips = np.array([[0.0, 0.5, -0.1], [0.3, 1.0, 0.5], [0.0, 1.2, 1.1], [0.0, 0.5, 0.5]])
    np.testing.assert_allclose(cross_track_errors(square, tips),
                               [0.1, 0.3, np.hypot(0.2, 0.1), 0.5])


def test_base_position_offset_is_fitted_with_the_factors(synthetic):
    pressures, tips = synthetic
    offset = np.array([2e-3, -3e-3, 1e-3])
    fit = identify('cbha', pressures, tips + offset, base_position=True)
    assert fit.names[-3:] == ('base_position.x', 'base_position.y', 'base_position.z')
    assert np.all(np.abs(fit.values[-3:] - offset) <= 3.0 * fit.standard_errors[-3:])
    assert np.all(fit.standard_errors[-3:] < 0.5e-3)
    assert np.all(np.abs(fit.values[:8] - TRUTH) <= 3.0 * fit.standard_errors[:8])
    assert fit.calibration.base_position == pytest.approx(tuple(fit.values[-3:]))
    assert fit.rms_after < 1.5 * np.sqrt(3.0) * NOISE


def _write_swept_bag(path, latency, noise):
    """Write slow sinusoidal commands (100 Hz, 12 s) and the tips (50 Hz) of the TRUTH plant."""
    # the plant sees the commands behind a link of `latency` and the 10 ms valves
    command_times = 1.0 + np.arange(1200) * 0.01
    frequency = np.array([0.05, 0.07, 0.09, 0.06, 0.08, 0.1])
    phase = np.arange(6) * 1.1
    commands = 75e3 + 50e3 * np.sin(2 * np.pi * frequency * (command_times[:, None] - 1.0)
                                    + phase)
    tip_times = 1.5 + np.arange(500) * 0.02
    acting = valve_pressures(command_times, commands, tip_times, latency, 0.01)
    tips = TipPredictor('cbha', parameter_names(load_scene('cbha')), acting)(TRUTH)
    measured = tips + np.random.default_rng(4).normal(0.0, noise, tips.shape)
    _write_session(path, command_times, commands, tip_times, measured)


def test_cbha_identify_estimates_the_link_latency_it_was_not_given(tmp_path, capsys):
    _write_swept_bag(tmp_path / 'bag', latency=0.030, noise=5e-5)
    assert main([str(tmp_path / 'bag'), '--output', str(tmp_path / 'out'), '--latency',
                 '0.003', '--fit-latency', '--pressure-source', 'commanded']) == 0
    report = (tmp_path / 'out' / 'cbha_identified_report.txt').read_text()
    assert any(line.split()[:1] == ['latency'] and line.split()[2:3] == ['ms']
               for line in report.splitlines())
    fitted = json.loads((tmp_path / 'out' / 'cbha_identified.json').read_text())
    latency = fitted['parameters']['latency']['value']
    error = fitted['parameters']['latency']['standard_error']
    assert abs(latency - 0.030) <= 3.0 * error
    assert error < 2e-3
    identified = load_scene(tmp_path / 'out' / 'cbha_identified.yaml')
    probe = np.array([120e3, 10e3, 60e3, 30e3, 140e3, 0.0])
    plant = TipPredictor('cbha', parameter_names(identified), probe[None])(TRUTH)[0]
    assert np.linalg.norm(identified.forward(probe).effector_positions[-1] - plant) < 0.5e-3


def test_cable_gains_of_a_tendon_trunk_are_recovered():
    """A beam trunk has no sections: its cables' gains are the parameters (tension in N)."""
    scene = load_scene('tendon_6f_8c')
    names = parameter_names(scene)
    assert names == tuple(f'actuator_gain.{a}' for a in scene.actuator_names)
    truth = np.array([0.9, 1.1, 1.05, 0.95, 1.08, 0.92, 1.0, 1.12])
    rng = np.random.default_rng(12)
    tensions = rng.uniform(0.0, 1.0, (20, 8)) * scene.upper_bounds
    clean = TipPredictor('tendon_6f_8c', names, tensions)(truth)
    fit = identify('tendon_6f_8c', tensions, clean + rng.normal(0.0, 1e-4, clean.shape))
    assert fit.rms_before > 5 * fit.rms_after
    assert np.all(np.abs(fit.values - truth) <= 3.0 * fit.standard_errors)
    assert np.all(fit.standard_errors < 0.05)
    assert fit.calibration.actuator_gain == pytest.approx(dict(zip(scene.actuator_names,
                                                                   fit.values)))


def test_valve_names_map_the_recorded_commands_to_the_scene_order():
    from cbha_inverse.identify.cli import command_order
    scene = load_scene('cbha')
    valves = ['outer_left', 'inner_over', 'inner_right', 'inner_left', 'outer_over', 'outer_right']
    commands = np.array([[float(scene.actuator_names.index(v)) for v in valves]])
    np.testing.assert_array_equal(commands[:, command_order(scene, ','.join(valves))],
                                  [np.arange(6.0)])
    np.testing.assert_array_equal(command_order(scene, None), np.arange(6))
    with pytest.raises(ValueError, match='must be a permutation'):
        command_order(scene, 'inner_over,outer_over')


class _Terminal(io.StringIO):

    def isatty(self):
        return True


def test_progress_is_one_updating_line():
    terminal = _Terminal()
    progress = ProgressLine(terminal)
    for message in ('evaluation 1: 10.0 mm', 'evaluation 2: 9.5 mm', 'evaluation 10: 1 mm'):
        progress(message)
    progress.close()
    text = terminal.getvalue()
    assert text.count('\n') == 1 and text.endswith('\n')
    assert text.split('\r')[-1].rstrip() == 'evaluation 10: 1 mm'
    # into a file: a line at most every period, and the last one at the end
    now = [0.0]
    written = io.StringIO()
    progress = ProgressLine(written, period=5.0, clock=lambda: now[0])
    for k in range(20):
        now[0] = float(k)
        progress(f'evaluation {k}')
    progress.close()
    assert written.getvalue().splitlines() == [
        'evaluation 0', 'evaluation 5', 'evaluation 10', 'evaluation 15', 'evaluation 19']
    verbose, quiet = io.StringIO(), io.StringIO()
    for mode, stream in (('verbose', verbose), ('quiet', quiet)):
        progress = ProgressLine(stream, mode=mode)
        for k in range(3):
            progress(f'evaluation {k}')
        progress.close()
    assert verbose.getvalue().splitlines() == ['evaluation 0', 'evaluation 1', 'evaluation 2']
    assert quiet.getvalue() == ''


def test_cbha_identify_verbose_prints_every_evaluation_and_quiet_none(tmp_path, capsys):
    # tips of the nominal scene: the fit starts at its optimum and ends after few evaluations
    commands = np.random.default_rng(6).uniform(0.0, 150e3, (8, 6))
    names = parameter_names(load_scene('cbha'))
    _write_bag(tmp_path / 'bag', commands, TipPredictor('cbha', names, commands)(
        np.ones(len(names))))
    shown = {}
    for flag in ('--verbose', '--quiet'):
        assert main([str(tmp_path / 'bag'), '--output', str(tmp_path / flag), flag,
                     '--max-samples', '12']) == 0
        out = capsys.readouterr().out
        evaluations = int(re.search(r'(\d+) forward evaluations', out).group(1))
        shown[flag] = [int(line.split()[1].rstrip(':')) for line in out.splitlines()
                       if line.startswith('evaluation ') and ': tip RMS' in line]
        shown[flag].append(evaluations)
    # every evaluation of the residuals on its own line (those of the Jacobian are not);
    # off a terminal the default shows at most one line per 5 s
    *verbose, evaluations = shown['--verbose']
    assert len(verbose) >= 10 and verbose == sorted(set(verbose)), verbose
    assert verbose[0] == 1 and verbose[-1] <= evaluations, shown
    assert shown['--quiet'] == [evaluations]
    with pytest.raises(SystemExit, match='2'):
        main([str(tmp_path / 'bag'), '--quiet', '--verbose'])
