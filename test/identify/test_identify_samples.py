"""
Acting pressures of a session: the valve model, measured-pressure interpolation, source choice.

The valve line (latency + first-order valves, run by cbha_sim) against the exponential step's
closed form at arbitrary tick times; the interpolation of a measured series against closed forms;
bags written with rosbags whose ``pressure_measured`` differs from the commands: the samples
follow the measurements, ``auto`` falls back to the commands without them, invalid measurements
are dropped and counted, and cbha_identify fits (and names) the measured pressures.
"""

from cbha_inverse.identify.cli import main
from cbha_inverse.identify.fit import parameter_names, TipPredictor
from cbha_inverse.identify.samples import (IdentificationError, interpolate_pressures,
                                           quasi_static_samples, read_session, valve_pressures)
from cbha_inverse.scene import load_scene
from cbha_inverse.sim.valves import first_order_step, ValveLine
import numpy as np
import pytest
from session_bags import write_session_bag

TAU = 0.01
LATENCY = 0.003
TRUTH = np.array([0.85, 1.1, 0.9, 1.05, 1.1, 0.95, 1.08, 0.92])


def test_first_order_step_is_the_exponential_closed_form():
    p0, s = np.array([10e3, 80e3]), np.array([50e3, 20e3])
    for elapsed in (0.0, 0.004, 0.01, 0.05):
        np.testing.assert_allclose(first_order_step(p0, s, elapsed, TAU),
                                   s + (p0 - s) * np.exp(-elapsed / TAU), rtol=1e-15)
    # broadcast over (N, 1) intervals, and tau = 0: the set-point at once
    elapsed = np.array([[0.0], [0.02]])
    assert first_order_step(p0, s, elapsed, TAU).shape == (2, 2)
    np.testing.assert_array_equal(first_order_step(p0, s, elapsed, 0.0), [s, s])


def _step_response(c, t, t0):
    """Return the closed form of a step ``c`` sent at ``t0``: c (1 - exp(-(t - t0 - L) / tau))."""
    return np.where(t >= t0 + LATENCY, c * -np.expm1(-(t - t0 - LATENCY) / TAU), 0.0)


def test_valve_line_is_exact_at_any_tick_times():
    """Ticks that straddle an arrival, two arrivals within one tick: the closed form each time."""
    valves = ValveLine(2, LATENCY, TAU)
    c = np.array([60e3, 30e3])
    valves.advance(0.0)
    valves.send(0.0, c)
    ticks = np.array([0.002, 0.0101, 0.013, 0.031, 0.0312, 0.08])
    got = np.array([valves.advance(t) for t in ticks])
    np.testing.assert_allclose(got, _step_response(c, ticks[:, None], 0.0), rtol=1e-12,
                               atol=1e-9)
    # two commands arrive between two ticks: up at 0.083, down at 0.088, evaluated at 0.1
    valves.send(0.080, 2 * c)
    valves.send(0.085, np.zeros(2))
    p = got[-1]
    p = c + (p - c) * np.exp(-(0.083 - 0.080) / TAU)               # still toward c
    p = 2 * c + (p - 2 * c) * np.exp(-(0.088 - 0.083) / TAU)       # toward 2 c
    p = p * np.exp(-(0.1 - 0.088) / TAU)                           # toward 0
    np.testing.assert_allclose(valves.advance(0.1), p, rtol=1e-12)
    # the batch model of cbha_identify gives the same pressures (same equation, other recursion)
    batch = valve_pressures(np.array([0.0, 0.080, 0.085]), np.array([c, 2 * c, 0 * c]),
                            np.append(ticks, 0.1), LATENCY, TAU)
    np.testing.assert_allclose(batch, np.vstack([got, p]), rtol=1e-12, atol=1e-9)


def test_valve_line_clock_jump_back_is_a_pause_and_reset_vents():
    valves = ValveLine(1, LATENCY, TAU)
    valves.send(1.0, [100.0])
    before = valves.advance(1.013)
    np.testing.assert_allclose(before, _step_response(100.0, 1.013, 1.0))
    np.testing.assert_allclose(valves.advance(0.5), before)   # a looped bag: nothing moves
    np.testing.assert_allclose(valves.advance(0.51), 100.0 + (before - 100.0) * np.exp(-1.0))
    valves.reset()
    np.testing.assert_array_equal(valves.advance(2.0), [0.0])
    with pytest.raises(ValueError, match='shape'):
        valves.send(2.0, [1.0, 2.0])
    with pytest.raises(ValueError, match='finite'):
        ValveLine(1, -1.0, TAU)


def test_interpolation_matches_closed_forms():
    rng = np.random.default_rng(1)
    t = np.sort(rng.uniform(0.0, 1.0, 40))
    a, b = np.array([1e3, -2e3]), np.array([5e4, 3e4])
    at = rng.uniform(t[0], t[-1], 200)
    values, covered = interpolate_pressures(t, a + b * t[:, None], at)
    # a linear series is reproduced exactly
    np.testing.assert_allclose(values, a + b * at[:, None], rtol=1e-12)
    assert covered.all()
    # f = t^2: the chord at the midpoint of [t_i, t_i+1] exceeds f by h^2 / 4
    mid, h = (t[:-1] + t[1:]) / 2, np.diff(t)
    values, _ = interpolate_pressures(t, (t ** 2)[:, None], mid)
    np.testing.assert_allclose(values[:, 0] - mid ** 2, h ** 2 / 4, rtol=1e-9, atol=1e-15)
    # outside the series, or in a gap longer than max_gap: not covered
    _, covered = interpolate_pressures(np.array([0.0, 0.1, 0.5]), np.zeros((3, 1)),
                                       np.array([-0.01, 0.0, 0.05, 0.3, 0.5, 0.51]),
                                       max_gap=0.2)
    np.testing.assert_array_equal(covered, [False, True, True, False, True, False])


def _write_bag(path, commands=(), measured=(), tips=()):
    """Write ``(t [s], values)`` commands, measured pressures and tips into a rosbag2 bag."""
    write_session_bag(path, commands, measured, tips)


HOLD = 0.5
JUMP = 0.02      # the measured pressure reaches its new value 20 ms after the command


def _session(rng, holds, with_measured=True, tip_of=None):
    """
    Return commands, measured pressures, tips (``(t, values)`` lists) and the reached pressures.

    Commands held ``HOLD`` s each from t = 1 s; measured pressures every 10 ms that differ from
    the commands (a valve that misses its set-point by up to 20 kPa, differently each time) and
    jump to their new value ``JUMP`` after each command; tips at 50 Hz.
    """
    commands = rng.uniform(20e3, 130e3, (holds, 6))
    reached = np.clip(commands + rng.uniform(-20e3, 20e3, commands.shape), 0.0, 150e3)
    starts = 1.0 + HOLD * np.arange(holds)
    grid = np.arange(1.0, starts[-1] + HOLD, 0.01)
    hold_of = np.searchsorted(starts + JUMP, grid, side='right') - 1
    measured = [(t, reached[k] if k >= 0 else np.zeros(6)) for t, k in zip(grid, hold_of)]
    tip_times = np.arange(1.0, starts[-1] + HOLD, 0.02) + 0.005
    tip_hold = np.searchsorted(starts + JUMP, tip_times, side='right') - 1
    tips = (np.zeros((holds, 3)) if tip_of is None else tip_of(reached))[np.maximum(tip_hold, 0)]
    return (list(zip(starts, commands)), measured if with_measured else [],
            list(zip(tip_times, tips)), reached)


def test_samples_follow_the_measured_pressures_not_the_commands(tmp_path):
    commands, measured, tips, reached = _session(np.random.default_rng(2), 8)
    _write_bag(tmp_path / 'bag', commands, measured, tips)
    session = read_session(tmp_path / 'bag')
    assert session.measured_dropped == 0 and session.measured.shape == (len(measured), 6)
    for source in ('auto', 'measured'):
        samples = quasi_static_samples(session, max_samples=1000, pressure_source=source)
        assert samples.pressure_source == 'measured'
        hold = np.floor((samples.times - JUMP) / HOLD).astype(int)
        np.testing.assert_allclose(samples.pressures, reached[hold], rtol=1e-12)
        # none within the settle time (50 ms) after a jump of the measured pressures
        assert np.all((samples.times - JUMP) % HOLD >= 0.05 - 1e-9)
    commanded = quasi_static_samples(session, max_samples=1000, pressure_source='commanded')
    assert commanded.pressure_source == 'commanded'
    hold = np.floor((commanded.times - LATENCY) / HOLD).astype(int)
    command_values = np.array([c for _, c in commands])
    # settled within 2 kPa over 50 ms = within 2 kPa / (e^5 - 1) = 14 Pa of the set-point
    np.testing.assert_allclose(commanded.pressures, command_values[hold], rtol=0.0, atol=14.0)
    assert np.abs(command_values - reached).max() > 5e3   # the two sources really differ


def test_measured_latency_looks_the_measurements_up_later(tmp_path):
    """Measurements received 30 ms late give the same samples with measured_latency 0.03."""
    commands, measured, tips, reached = _session(np.random.default_rng(2), 4)
    late = [(t + 0.03, values) for t, values in measured]
    _write_bag(tmp_path / 'bag', commands, late, tips)
    session = read_session(tmp_path / 'bag')
    samples = quasi_static_samples(session, max_samples=1000, measured_latency=0.03)
    hold = np.floor((samples.times - JUMP) / HOLD).astype(int)
    np.testing.assert_allclose(samples.pressures, reached[hold], rtol=1e-12)
    # without it, every jump (and the start of the series) is seen 30 ms late
    unshifted = quasi_static_samples(session, max_samples=1000)
    assert unshifted.times[0] >= 0.03 + 0.05 - 1e-9
    hold = np.floor((unshifted.times - JUMP - 0.03) / HOLD).astype(int)
    np.testing.assert_allclose(unshifted.pressures, reached[hold], rtol=1e-12)
    assert not np.array_equal(unshifted.times, samples.times)


def test_auto_falls_back_to_the_commands_without_pressure_measured(tmp_path):
    commands, _, tips, _ = _session(np.random.default_rng(2), 4, with_measured=False)
    _write_bag(tmp_path / 'bag', commands, (), tips)
    session = read_session(tmp_path / 'bag')
    assert session.measured_times is None
    samples = quasi_static_samples(session, max_samples=1000)
    assert samples.pressure_source == 'commanded'
    np.testing.assert_allclose(samples.pressures, quasi_static_samples(
        session, max_samples=1000, pressure_source='commanded').pressures)
    with pytest.raises(IdentificationError, match='pressure_measured not recorded'):
        quasi_static_samples(session, pressure_source='measured')
    with pytest.raises(ValueError, match='pressure_source'):
        quasi_static_samples(session, pressure_source='sensor')


def test_invalid_measurements_are_dropped_and_counted(tmp_path):
    commands, measured, tips, reached = _session(np.random.default_rng(2), 4)
    broken = list(measured)
    broken[30] = (broken[30][0], broken[30][1][:5])                    # wrong length
    broken[60] = (broken[60][0], np.full(6, np.nan))                   # not finite
    broken[90] = (broken[90][0], np.append(broken[90][1][:5], np.inf))
    _write_bag(tmp_path / 'bag', commands, broken, tips)
    session = read_session(tmp_path / 'bag')
    assert session.measured_dropped == 3 and len(session.measured) == len(measured) - 3
    samples = quasi_static_samples(session, max_samples=1000)
    assert samples.measured_dropped == 3 and samples.pressure_source == 'measured'
    assert np.all(np.isfinite(samples.pressures))
    hold = np.floor((samples.times - JUMP) / HOLD).astype(int)
    np.testing.assert_allclose(samples.pressures, reached[hold], rtol=1e-12)
    # a series with no valid message is refused, not silently replaced by the commands
    _write_bag(tmp_path / 'short', commands, [(t, v[:3]) for t, v in measured], tips)
    with pytest.raises(IdentificationError, match=r'all \d+ messages dropped: not 6 finite'):
        quasi_static_samples(read_session(tmp_path / 'short'))
    # a gap in the measurements longer than the settle time: no sample in it
    gap = [(t, v) for t, v in measured if not 1.6 < t < 1.8]
    _write_bag(tmp_path / 'gap', commands, gap, tips)
    samples = quasi_static_samples(read_session(tmp_path / 'gap'), max_samples=1000)
    assert not np.any((samples.times > 0.6 - 0.01) & (samples.times < 0.8 + 0.05))


def test_cbha_identify_fits_the_measured_pressures_and_names_them(tmp_path, capsys):
    """Tips of the plant at the measured pressures: the fit through them reproduces the plant."""
    names = parameter_names(load_scene('cbha'))

    def plant(pressures):
        return TipPredictor('cbha', names, pressures)(TRUTH)

    commands, measured, tips, reached = _session(np.random.default_rng(4), 12, tip_of=plant)
    _write_bag(tmp_path / 'bag', commands, measured, tips)
    assert main([str(tmp_path / 'bag'), '--output', str(tmp_path / 'out'),
                 '--max-samples', '24']) == 0
    report = (tmp_path / 'out' / 'cbha_identified_report.txt').read_text()
    assert 'pressures: measured\n' in report
    assert 'pressures: measured' in capsys.readouterr().out
    identified = load_scene(tmp_path / 'out' / 'cbha_identified.yaml')
    probe = np.array([120e3, 10e3, 60e3, 30e3, 140e3, 0.0])
    predicted = identified.forward(probe).effector_positions[-1]
    assert np.linalg.norm(predicted - plant(probe[None])[0]) < 1e-4
    # the flag reaches the selection: measured pressures asked for, none recorded ('auto' fits)
    commands, _, tips, _ = _session(np.random.default_rng(4), 12, tip_of=plant)
    _write_bag(tmp_path / 'no_measured', commands, (), tips)
    assert main([str(tmp_path / 'no_measured'), '--output', str(tmp_path / 'out2'),
                 '--pressure-source', 'measured']) == 1
    assert 'pressure_measured not recorded' in capsys.readouterr().err
    assert not (tmp_path / 'out2').exists()


def test_pooled_samples_keep_each_session_and_its_pressures_at_another_delay():
    from cbha_inverse.identify.cli import _delayed_pressures
    from cbha_inverse.identify.samples import acting_pressures, pooled_samples, Session
    sessions, parts = [], []
    for k, level in enumerate((40e3, 90e3)):
        command_times = 10.0 * k + np.arange(0.0, 2.0, 0.5)
        commands = level + 10e3 * np.arange(4)[:, None] * np.ones((1, 2))
        tip_times = 10.0 * k + np.arange(0.01, 2.0, 0.02)
        session = Session(command_times, commands, tip_times, np.zeros((tip_times.size, 3)))
        sessions.append(session)
        parts.append(quasi_static_samples(session, max_samples=10 ** 6, latency=LATENCY,
                                          valve_time_constant=TAU))
    pooled = pooled_samples(parts, 30)
    assert len(pooled.tips) == 30
    assert pooled.quasi_static == parts[0].quasi_static + parts[1].quasi_static
    assert pooled.pressure_source == 'commanded' and pooled.delay == LATENCY
    # evenly spread over the pool, in session order: both sessions, first then second
    assert np.all(np.diff(pooled.part) >= 0) and set(pooled.part) == {0, 1}
    order = np.array([1, 0])
    for delay in (LATENCY, 0.02):
        got = _delayed_pressures(sessions, pooled, order, TAU, delay)
        for k, session in enumerate(sessions):
            mine = pooled.part == k
            expected = acting_pressures(session, pooled.receive_times[mine], 'commanded',
                                        delay, TAU)[0][:, order]
            np.testing.assert_array_equal(got[mine], expected)
    # at the alignment delay the pooled pressures are the samples' own
    np.testing.assert_array_equal(_delayed_pressures(sessions, pooled, np.arange(2), TAU,
                                                     LATENCY), pooled.pressures)
