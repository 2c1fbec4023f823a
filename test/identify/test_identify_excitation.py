"""
Excitation programs (cbha_inverse.identify.excitation) against closed forms.

The timeline is checked against its definition written out independently (hold i from
``r + i (r + h)`` to ``r + i (r + h) + h``, straight lines between consecutive set-points),
continuity and slopes by finite differences, the bounds on dense grids, the named programs of the
CBHA scene against the literal pressure tables they must produce, and every malformed program
file against the file and key its error must name.
"""

from cbha_inverse.errors import ConfigError
from cbha_inverse.identify.excitation import (
    bend_holds, ExcitationProgram, extension_holds, make_program, mid_range, program_names,
    read_program_file, section_groups)
from cbha_inverse.paths import config_path
from cbha_inverse.robot.safety import command_bounds
from cbha_inverse.scene import load_scene
import numpy as np
import pytest

P = 150000.0
M = 75000.0


@pytest.fixture(scope='module')
def cbha():
    return load_scene('cbha')


def _random_program(rng, n=4, m=3, hold_time=2.5, ramp_time=0.7):
    lower = rng.uniform(-10.0, 0.0, m)
    upper = lower + rng.uniform(1.0, 100.0, m)
    holds = lower + rng.uniform(0.0, 1.0, (n, m)) * (upper - lower)
    start = lower + rng.uniform(0.0, 1.0, m) * (upper - lower)
    end = lower + rng.uniform(0.0, 1.0, m) * (upper - lower)
    return ExcitationProgram(holds, lower, upper, hold_time=hold_time, ramp_time=ramp_time,
                             start=start, end=end), holds, start, end


def _reference(t, holds, start, end, h, r):
    """Return the definition, written out: set-points, the times they are reached and left."""
    points = [start] + list(holds) + [end]
    reached = [0.0] + [r + i * (r + h) for i in range(len(holds))] + [len(holds) * (r + h) + r]
    left = [0.0] + [reached[i + 1] + h for i in range(len(holds))] + [reached[-1]]
    if t <= 0.0:
        return start
    for j in range(len(points) - 1):
        if reached[j] <= t <= left[j]:
            return points[j]
        if left[j] < t < reached[j + 1]:
            return points[j] + (t - left[j]) / r * (points[j + 1] - points[j])
    return end


def test_holds_and_ramps_follow_their_definition():
    rng = np.random.default_rng(3)
    h, r = 2.5, 0.7
    program, holds, start, end = _random_program(rng, hold_time=h, ramp_time=r)
    assert program.duration == pytest.approx(5 * r + 4 * h, abs=1e-12)
    for i, (t_start, t_end, pressures) in enumerate(program.holds):
        assert t_start == pytest.approx(r + i * (r + h), abs=1e-12)
        assert t_end == pytest.approx(t_start + h, abs=1e-12)
        np.testing.assert_array_equal(pressures, holds[i])
        inside = np.linspace(t_start, t_end, 7)
        np.testing.assert_allclose(program.pressures_at(inside), np.tile(holds[i], (7, 1)),
                                   rtol=0, atol=1e-12)
        assert [program.hold_index(t) for t in inside] == [i] * 7
    times = np.concatenate([[-1.0], rng.uniform(0.0, program.duration, 400),
                            [program.duration, program.duration + 5.0]])
    expected = np.array([_reference(t, holds, start, end, h, r) for t in times])
    np.testing.assert_allclose(program.pressures_at(times), expected, rtol=0, atol=1e-10)
    np.testing.assert_allclose(program.pressures_at(0.0), start, atol=0)
    np.testing.assert_allclose(program.pressures_at(program.duration), end, atol=0)
    assert program.pressures_at(1.3).shape == (3,)
    assert program.pressures_at(np.zeros((2, 5))).shape == (2, 5, 3)
    # ramps, before and after: no hold
    outside = (-1.0, 0.0, 0.5 * r, r + h + 0.5 * r, program.duration)
    assert [program.hold_index(t) for t in outside] == [-1] * 5
    # the end, to the clock's resolution of 1 ns
    assert not program.finished(program.duration - 2e-9)
    assert program.finished(program.duration - 5e-10) and program.finished(program.duration)


def test_ramps_are_linear_and_continuous():
    rng = np.random.default_rng(5)
    h, r = 1.0, 0.4
    program, holds, start, end = _random_program(rng, hold_time=h, ramp_time=r)
    points = np.vstack([start, holds, end])
    left = np.array([0.0] + [r + i * (r + h) + h for i in range(len(holds))])
    e = 1e-4
    for j, t_left in enumerate(left):
        # central differences at three points of each ramp: the constant slope (b - a) / r
        for t in t_left + np.array([0.2, 0.5, 0.8]) * r:
            slope = (program.pressures_at(t + e) - program.pressures_at(t - e)) / (2 * e)
            np.testing.assert_allclose(slope, (points[j + 1] - points[j]) / r, rtol=1e-6,
                                       atol=1e-6)
    # no step anywhere: on a fine grid consecutive values differ by at most the steepest slope
    dt = 1e-3
    grid = np.arange(-0.1, program.duration + 0.1, dt)
    jumps = np.abs(np.diff(program.pressures_at(grid), axis=0))
    steepest = np.abs(np.diff(points, axis=0)).max(axis=0) / r
    assert np.all(jumps <= steepest * dt * (1 + 1e-9) + 1e-9)


def test_every_value_stays_within_the_bounds():
    rng = np.random.default_rng(11)
    for _ in range(20):
        program, *_ = _random_program(
            rng, n=int(rng.integers(1, 6)), m=int(rng.integers(1, 8)),
            hold_time=rng.uniform(0.01, 3), ramp_time=rng.uniform(0.01, 2))
        values = program.pressures_at(np.linspace(-1.0, program.duration + 1.0, 3001))
        assert np.all(values >= program.lower) and np.all(values <= program.upper)
    # holds at the bounds themselves: the ramps between them touch but never cross them
    lower, upper = np.zeros(2), np.array([0.3, 150000.0])
    program = ExcitationProgram([upper, lower, upper], lower, upper, hold_time=0.1,
                                ramp_time=0.3)
    values = program.pressures_at(np.linspace(0.0, program.duration, 10001))
    assert np.all(values >= lower) and np.all(values <= upper)
    assert values.max(axis=0).tolist() == upper.tolist()


def test_named_programs_of_the_cbha_scene(cbha):
    assert cbha.actuator_sections == ('inner',) * 3 + ('outer',) * 3
    assert program_names(cbha.actuator_sections) == (
        'all', 'bends', 'extension', 'inner_bends', 'outer_bends')
    bends = [[P, 0, 0, M, M, M], [0, P, 0, M, M, M], [0, 0, P, M, M, M],
             [M, M, M, P, 0, 0], [M, M, M, 0, P, 0], [M, M, M, 0, 0, P]]
    extension = [[f * P] * 6 for f in (0.0, 0.25, 0.5, 0.75, 1.0)]
    expected = {'bends': bends, 'inner_bends': bends[:3], 'outer_bends': bends[3:],
                'extension': extension, 'all': extension + bends}
    for name, holds in expected.items():
        program = make_program(cbha, name)
        np.testing.assert_array_equal(program.hold_pressures, np.array(holds, dtype=float))
        assert program.hold_time == 3.0 and program.ramp_time == 1.0
        np.testing.assert_array_equal(program.start, [M] * 6)
        np.testing.assert_array_equal(program.end, [M] * 6)
        assert program.duration == pytest.approx(len(holds) * 4.0 + 1.0)
    assert 'outer_right max' in make_program(cbha, 'outer_bends').labels[1]
    # a driver cap (cbha_excite max_pressure) is the programs' new maximum and moves mid range
    capped = make_program(cbha, 'outer_bends', hold_time=0.2, ramp_time=0.1,
                          bounds=command_bounds(cbha.lower_bounds, cbha.upper_bounds, 100e3))
    np.testing.assert_array_equal(capped.hold_pressures[0], [50e3] * 3 + [100e3, 0, 0])
    assert capped.duration == pytest.approx(3 * 0.2 + 4 * 0.1)
    with pytest.raises(ValueError, match='unknown excitation program .outerbends'):
        make_program(cbha, 'outerbends')


def test_scenes_without_sections_have_the_extension_only():
    scene = load_scene('tendon_6f_8c')
    assert program_names(scene.actuator_sections) == ('extension',)
    assert make_program(scene, 'extension').n_holds == 5
    with pytest.raises(ValueError, match="has \\['extension'\\]"):
        make_program(scene, 'bends')


def test_builders_on_their_own():
    lower, upper = np.array([0.0, 10.0, -2.0]), np.array([4.0, 20.0, 2.0])
    groups = section_groups(['a', None, 'a'])
    assert groups == {'a': (0, 2)}
    holds, labels = bend_holds(lower, upper, groups, names=['x', 'y', 'z'])
    np.testing.assert_array_equal(holds, [[4.0, 15.0, -2.0], [0.0, 15.0, 2.0]])
    assert labels[1].startswith('a bend: z max')
    holds, _ = extension_holds(lower, upper, (0.0, 0.5))
    np.testing.assert_array_equal(holds, [[0.0, 10.0, -2.0], [2.0, 15.0, 0.0]])
    np.testing.assert_array_equal(mid_range(lower, upper), [2.0, 15.0, 0.0])
    with pytest.raises(ValueError, match='fractions'):
        extension_holds(lower, upper, (1.5,))
    with pytest.raises(ValueError, match='no section'):
        bend_holds(lower, upper, {})


@pytest.mark.parametrize('change, match', [
    ({'hold_time': 0.0}, 'hold_time must be a finite number of seconds > 0'),
    ({'hold_time': -1.0}, 'hold_time'),
    ({'ramp_time': float('nan')}, 'ramp_time'),
    ({'ramp_time': float('inf')}, 'ramp_time'),
    ({'ramp_time': 'soon'}, 'ramp_time must be a number'),
    ({'holds': [[1.0, 1.0, 1.0]]}, r'holds must be an \(n >= 1, 2\) array'),
    ({'holds': np.zeros((0, 2))}, 'holds must be'),
    ({'holds': [[1.0, float('nan')]]}, 'hold 0 must be finite'),
    ({'holds': [[1.0, 1.0], [1.0, 3.5]]}, r'hold 1: value 3.5 of actuator 1 is outside its '
     r'bounds \[0, 3\]'),
    ({'start': [5.0, 1.0]}, 'start: value 5'),
    ({'end': [1.0]}, 'end must have 2 values'),
    ({'labels': ['one', 'two']}, 'labels must have 1 entries'),
    ({'lower': [0.0, 4.0]}, 'exceed upper'),
    ({'upper': [2.0, float('inf')]}, 'bounds must be finite'),
])
def test_invalid_programs_are_refused(change, match):
    arguments = {'holds': [[1.0, 1.0]], 'lower': [0.0, 0.0], 'upper': [2.0, 3.0]}
    arguments.update(change)
    holds, lower, upper = (arguments.pop(k) for k in ('holds', 'lower', 'upper'))
    with pytest.raises(ValueError, match=match):
        ExcitationProgram(holds, lower, upper, **arguments)


def test_times_must_be_finite():
    program = ExcitationProgram([[1.0]], [0.0], [2.0])
    with pytest.raises(ValueError, match='time must be finite'):
        program.pressures_at(float('nan'))
    assert not program.hold_pressures.flags.writeable


def test_the_shipped_example_file(cbha):
    path = config_path('excitation', 'cbha_example.yaml')
    holds, labels = read_program_file(path, cbha.actuator_names, cbha.lower_bounds,
                                      cbha.upper_bounds)
    np.testing.assert_array_equal(holds, [[M, M, M, P, P, 0], [M, M, M, 0, P, P],
                                          [M, M, M, P, 0, P]])
    assert labels == tuple(f'cbha_example.yaml hold {i}' for i in range(3))
    # by name relative to config/, with a cap that the example (150 kPa) then violates
    program = make_program(cbha, 'excitation/cbha_example.yaml', hold_time=0.5)
    np.testing.assert_array_equal(program.hold_pressures, holds)
    with pytest.raises(ConfigError) as error:
        make_program(cbha, 'excitation/cbha_example.yaml',
                     bounds=command_bounds(cbha.lower_bounds, cbha.upper_bounds, 120e3))
    assert error.value.key == 'holds[0][3]' and error.value.path == str(path)
    assert '150000 is outside the bounds [0, 120000] of outer_over' in str(error.value)


@pytest.mark.parametrize('text, key, problem', [
    ('holds: []\n', 'holds', 'must be a non-empty list'),
    ('description: x\n', 'holds', 'must be a non-empty list'),
    ('holds: [[1.0, 2.0]]\nspeed: 3\n', 'speed', 'unknown key'),
    ('holds:\n  - [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\n  - [0.0, 0.0, 0.0]\n', 'holds[1]',
     'must be a list of 6 pressures (scene order'),
    ('holds: [[0.0, 0.0, 0.0, 0.0, 0.0, .nan]]\n', 'holds[0][5]', 'must be finite'),
    ('holds: [[0.0, 0.0, 0.0, 0.0, 0.0, true]]\n', 'holds[0][5]', 'must be a number'),
    ('holds: [[0.0, 0.0, 0.0, 0.0, 0.0, 1.0e5]]\n', 'holds[0][5]',
     "got text '1.0e5' (YAML reads exponent notation as a number only with a decimal point"),
    ('holds: [[0.0, 0.0, 0.0, 160000.0, 0.0, 0.0]]\n', 'holds[0][3]',
     '160000 is outside the bounds [0, 150000] of outer_over'),
    ('holds: [[0.0, 0.0, -1.0, 0.0, 0.0, 0.0]]\n', 'holds[0][2]', 'of inner_left'),
    ('holds: [42]\n', 'holds[0]', 'must be a list of 6 pressures or a mapping'),
    ('holds:\n  - {inner_over: 0.0, inner_right: 0.0, inner_left: 0.0, outer_over: 0.0,\n'
     '     outer_right: 0.0, outer_lft: 0.0}\n', 'holds[0].outer_lft', "no actuator 'outer_lft'"),
    ('holds:\n  - {inner_over: 0.0, inner_right: 0.0, inner_left: 0.0}\n', 'holds[0]',
     "misses actuators ['outer_over', 'outer_right', 'outer_left']"),
    ('holds:\n  - {inner_over: 0.0, inner_right: 0.0, inner_left: 0.0, outer_over: high,\n'
     '     outer_right: 0.0, outer_left: 0.0}\n', 'holds[0].outer_over',
     "must be a number, got text 'high'"),
    ('holds:\n  - {inner_over: 0.0, inner_right: 0.0, inner_left: 0.0, outer_over: 0.0,\n'
     '     outer_right: 200000.0, outer_left: 0.0}\n', 'holds[0].outer_right',
     'outside the bounds [0, 150000] of outer_right'),
    ('holds: [[0.0, 0.0\n', 'line 2', 'invalid YAML'),
    ('- [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\n', 'top level', 'must be a mapping'),
])
def test_program_file_errors_name_file_and_key(tmp_path, cbha, text, key, problem):
    path = tmp_path / 'holds.yaml'
    path.write_text(text)
    with pytest.raises(ConfigError) as error:
        make_program(cbha, str(path))
    assert error.value.path == str(path)
    assert error.value.key == key
    assert problem in error.value.problem


def test_a_missing_program_file(tmp_path, cbha):
    with pytest.raises(ConfigError) as error:
        make_program(cbha, str(tmp_path / 'nothing.yaml'))
    assert error.value.key == 'file' and 'no such file' in error.value.problem
