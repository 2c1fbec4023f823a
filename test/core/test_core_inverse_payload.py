"""InverseSolver.set_payload: a known tip mass in the model's loads."""

from cbha_inverse.scene import load_scene
from cbha_inverse.scene.calibration import Calibration
import numpy as np
import pytest


def _settle(solver, target, ticks=60):
    """Run ticks toward a fixed target; return the last actuation."""
    for _ in range(ticks):
        result = solver.step(target[None])
    return result.actuation


def test_a_known_payload_drives_the_loaded_plant_to_the_target_open_loop():
    """The scene with tip_payload_mass (independent reference) reaches the solver's target."""
    nominal = load_scene('cbha')
    loaded = load_scene('cbha', calibration=Calibration(tip_payload_mass=0.05))
    target = nominal.forward(np.array([6e4, 4e4, 2e4, 3e4, 5e4, 4e4]),
                             strict=True).effector_positions[-1]
    solver = nominal.make_inverse_solver()
    unaware = _settle(solver, target)
    solver.reset()
    solver.set_payload(0.05)
    aware = _settle(solver, target)
    miss_unaware = np.linalg.norm(loaded.forward(unaware, strict=True).effector_positions[-1]
                                  - target)
    miss_aware = np.linalg.norm(loaded.forward(aware, strict=True).effector_positions[-1]
                                - target)
    assert miss_unaware > 10e-3 and miss_aware < 0.5e-3, (miss_unaware, miss_aware)
    # and back to none: the nominal plant again
    solver.set_payload(0.0)
    again = _settle(solver, target)
    assert np.linalg.norm(nominal.forward(again, strict=True).effector_positions[-1]
                          - target) < 0.5e-3


def test_a_non_finite_payload_is_refused():
    solver = load_scene('cbha').make_inverse_solver()
    with pytest.raises(ValueError, match='finite'):
        solver.set_payload(float('nan'))


def test_a_limited_change_moves_the_payload_in_steps_and_the_loads_with_it():
    """max_change: the model's payload walks to the request; the loads are those of the mass."""
    solver = load_scene('cbha').make_inverse_solver()
    steps = [solver.set_payload(0.1, max_change=0.04) for _ in range(4)]
    np.testing.assert_allclose(steps, [0.04, 0.08, 0.1, 0.1])
    assert solver.payload == 0.1
    assert solver.set_payload(-0.05, max_change=0.02) == pytest.approx(0.08)
    exact = load_scene('cbha').make_inverse_solver()
    exact.set_payload(0.08)
    np.testing.assert_array_equal(solver._external, exact._external)
    assert solver.set_payload(0.0) == 0.0
    np.testing.assert_array_equal(solver._external, solver._unloaded)


def test_a_payload_prepared_off_the_tick_gives_the_ticks_own_linearisation():
    """set_payload then prepare: the next step does not linearise and equals one that does."""
    scene = load_scene('cbha')
    target = scene.forward(np.array([6e4, 4e4, 2e4, 3e4, 5e4, 4e4]),
                           strict=True).effector_positions[-1][None]
    prepared, inside = scene.make_inverse_solver(), scene.make_inverse_solver()
    for solver in (prepared, inside):
        _settle(solver, target[0], ticks=5)
        solver.prepare()
    prepared.set_payload(0.05)
    inside.set_payload(0.05)
    prepared.prepare()
    ahead, own = prepared.step(target), inside.step(target)
    # the prepared tick only solved; the other one linearised inside its step
    assert ahead.timings['assembly'] == 0.0 and own.timings['assembly'] > 0.0
    np.testing.assert_array_equal(ahead.actuation, own.actuation)
    # an unchanged payload keeps the prepared linearisation; a changed one drops it
    for solver in (prepared, inside):
        solver.prepare()
    prepared.set_payload(0.05)
    inside.set_payload(0.06)
    assert prepared.step(target).timings['assembly'] == 0.0
    assert inside.step(target).timings['assembly'] > 0.0
