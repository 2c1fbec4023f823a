"""InverseSolver.set_section_stiffness: the chain sections' stiffness factors in the model."""

from cbha_inverse.core.sections import check_section_factors, SECTION_FACTOR_BOUNDS
from cbha_inverse.scene import load_scene
from cbha_inverse.scene.calibration import Calibration
import numpy as np
import pytest

FACTORS = {'inner': 1.15, 'outer': 0.85}
TARGET_ACTUATION = np.array([6e4, 4e4, 2e4, 3e4, 5e4, 4e4])


@pytest.fixture(scope='module')
def scenes():
    """Return the nominal CBHA scene and the one built with FACTORS on its sections (oracle)."""
    return (load_scene('cbha'),
            load_scene('cbha', calibration=Calibration(section_stiffness=FACTORS)))


def _ticks(solver, target, ticks):
    """Run ticks toward a fixed target; return the actuations and effector positions."""
    out = [solver.step(target[None]) for _ in range(ticks)]
    return (np.array([r.actuation for r in out]),
            np.array([r.effector_positions for r in out]))


def test_factors_set_equal_a_solver_built_on_the_scaled_scene(scenes):
    """Same ticks, to round-off, as the scene whose sections are built scaled (the oracle)."""
    nominal, scaled = scenes
    assert nominal.section_links and tuple(FACTORS) == nominal.section_names
    target = nominal.forward(TARGET_ACTUATION, strict=True).effector_positions[-1]
    solver = nominal.make_inverse_solver()
    assert solver.section_names == ('inner', 'outer')
    applied = solver.set_section_stiffness([FACTORS['inner'], FACTORS['outer']])
    np.testing.assert_array_equal(applied, [1.15, 0.85])
    np.testing.assert_array_equal(solver.section_stiffness, [1.15, 0.85])
    oracle = scaled.make_inverse_solver()
    got, expected = _ticks(solver, target, 25), _ticks(oracle, target, 25)
    np.testing.assert_allclose(got[0], expected[0], rtol=1e-7, atol=1e-3)   # [Pa]
    np.testing.assert_allclose(got[1], expected[1], rtol=0.0, atol=1e-9)    # [m]
    # and the command differs from the nominal model's by far more than that
    unaware = _ticks(nominal.make_inverse_solver(), target, 25)[0]
    assert np.abs(unaware[-1] - expected[0][-1]).max() > 1e3


def test_factors_set_mid_run_relinearise_and_reach_the_scaled_plant(scenes):
    """Set after ticks of the nominal model: the next ticks bring the scaled plant to target."""
    nominal, scaled = scenes
    target = nominal.forward(TARGET_ACTUATION, strict=True).effector_positions[-1]
    solver = nominal.make_inverse_solver()
    unaware = _ticks(solver, target, 40)[0][-1]
    solver.set_section_stiffness([1.15, 0.85])
    aware = _ticks(solver, target, 40)[0][-1]
    miss = [np.linalg.norm(scaled.forward(a, strict=True).effector_positions[-1] - target)
            for a in (unaware, aware)]
    assert miss[0] > 3e-3 and miss[1] < 0.3e-3, miss
    # back to the model's own stiffness: the nominal plant again
    solver.set_section_stiffness([1.0, 1.0])
    again = _ticks(solver, target, 40)[0][-1]
    assert np.linalg.norm(nominal.forward(again, strict=True).effector_positions[-1]
                          - target) < 0.3e-3


def test_a_limited_change_moves_each_factor_in_steps(scenes):
    solver = scenes[0].make_inverse_solver()
    steps = [solver.set_section_stiffness([1.15, 0.85], max_change=0.06) for _ in range(3)]
    np.testing.assert_allclose(steps, [[1.06, 0.94], [1.12, 0.88], [1.15, 0.85]])
    np.testing.assert_allclose(solver.set_section_stiffness([1.0, 1.0], max_change=0.1),
                               [1.05, 0.95])
    # the tick's link stiffness is the nominal one times each link's factor
    nominal = scenes[0].model.stiffnesses
    links = scenes[0].section_links
    stiffness = solver._system.stiffness
    for factor, (first, count) in zip((1.05, 0.95), links.values()):
        np.testing.assert_allclose(stiffness[first:first + count],
                                   factor * nominal[first:first + count], rtol=1e-15)
    assert not stiffness.flags.writeable


@pytest.mark.parametrize('factors, match', [
    ([1.1], 'expected 2'),
    ([1.1, 1.0, 1.0], 'expected 2'),
    ([[1.1, 1.0]], 'expected 2'),
    ([np.nan, 1.0], 'not finite'),
    ([1.0, np.inf], 'not finite'),
    ([SECTION_FACTOR_BOUNDS[0] - 0.01, 1.0], 'outside'),
    ([1.0, SECTION_FACTOR_BOUNDS[1] + 0.01], 'outside'),
    ([0.0, 1.0], 'outside'),
])
def test_bad_factors_are_refused_and_change_nothing(scenes, factors, match):
    solver = scenes[0].make_inverse_solver()
    solver.set_section_stiffness([1.1, 0.9])
    with pytest.raises(ValueError, match=match):
        solver.set_section_stiffness(factors)
    np.testing.assert_array_equal(solver.section_stiffness, [1.1, 0.9])


def test_a_bad_max_change_is_refused(scenes):
    solver = scenes[0].make_inverse_solver()
    with pytest.raises(ValueError, match='max_change'):
        solver.set_section_stiffness([1.1, 0.9], max_change=-0.1)
    with pytest.raises(ValueError, match='max_change'):
        solver.set_section_stiffness([1.1, 0.9], max_change=float('nan'))


def test_the_check_names_its_reason():
    assert check_section_factors([1.0, 1.0], 2) is None
    assert check_section_factors([1.0], 2)[0] == 'wrong_length'
    assert check_section_factors([np.nan, 1.0], 2)[0] == 'not_finite'
    assert check_section_factors([3.0, 1.0], 2)[0] == 'out_of_range'


def test_a_chain_without_sections_takes_no_factor():
    solver = load_scene('tendon_6f_8c').make_inverse_solver()
    assert solver.section_names == ()
    with pytest.raises(ValueError, match='expected 0'):
        solver.set_section_stiffness([1.0])


GAINS = {'inner_over': 1.1, 'inner_right': 0.9, 'inner_left': 1.05, 'outer_over': 0.92,
         'outer_right': 1.08, 'outer_left': 0.95}


def test_gains_set_equal_a_solver_built_on_the_scene_with_those_gains(scenes):
    """Same ticks, to round-off, as the scene whose cavities are built with the gains."""
    nominal = scenes[0]
    target = nominal.forward(TARGET_ACTUATION, strict=True).effector_positions[-1]
    gains = [GAINS[name] for name in nominal.actuator_names]
    solver = nominal.make_inverse_solver()
    np.testing.assert_array_equal(solver.set_actuator_gain(gains), gains)
    oracle = load_scene('cbha', calibration=Calibration(actuator_gain=GAINS)).make_inverse_solver()
    got, expected = _ticks(solver, target, 25), _ticks(oracle, target, 25)
    np.testing.assert_allclose(got[0], expected[0], rtol=1e-7, atol=1e-3)   # [Pa]
    np.testing.assert_allclose(got[1], expected[1], rtol=0.0, atol=1e-9)    # [m]
    unaware = _ticks(nominal.make_inverse_solver(), target, 25)[0]
    assert np.abs(unaware[-1] - expected[0][-1]).max() > 1e3
    # rate-limited, and back to the scene's
    steps = solver.set_actuator_gain(np.ones(6), max_change=0.04)
    np.testing.assert_allclose(steps, [1.06, 0.94, 1.01, 0.96, 1.04, 0.99])
    solver.set_actuator_gain(np.ones(6))
    solver.reset()
    np.testing.assert_allclose(_ticks(solver, target, 25)[0][-1],
                               _ticks(nominal.make_inverse_solver(), target, 25)[0][-1],
                               rtol=1e-7, atol=1e-3)


@pytest.mark.parametrize('gains, match', [
    ([1.0] * 5, 'expected 6'), ([np.nan] + [1.0] * 5, 'not finite'),
    ([2.5] + [1.0] * 5, 'outside')])
def test_bad_gains_are_refused_and_change_nothing(scenes, gains, match):
    solver = scenes[0].make_inverse_solver()
    with pytest.raises(ValueError, match=match):
        solver.set_actuator_gain(gains)
    np.testing.assert_array_equal(solver.actuator_gain, np.ones(6))


def test_cables_take_no_gain():
    solver = load_scene('tendon_6f_8c').make_inverse_solver()
    with pytest.raises(ValueError, match='condensed cavities'):
        solver.set_actuator_gain(np.ones(len(solver.actuator_names)))
