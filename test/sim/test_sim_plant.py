"""The pure parts behind cbha_sim and cbha_demo: the plant and the tracking metrics."""

from cbha_inverse.core.obstacles import Obstacle
from cbha_inverse.metrics import plot_runs, tracking_errors, unblocked_errors
from cbha_inverse.scene import load_scene
from cbha_inverse.sim.plant import StaticPlant
import numpy as np
import pytest


def _root_reference(scene, actuation):
    """
    Solve ``f(q) + f_ext + J_a(q)ᵀ λ = 0`` with scipy's MINPACK (an independent nonlinear solver).

    Unknowns: the frames' displacements and rotation vectors from rest (``R = exp(φ) R_rest``),
    found by ten load steps of Powell's hybrid method; the residual is the test oracles' numpy
    one (internal wrenches, gravity, actuator loads), not the compiled kernels'.
    """
    from cbha_inverse.core.chain import ChainState, rest_state
    from oracles.chain_forces import internal_wrenches
    from oracles.loads import actuator_loads
    from oracles.so3 import so3_exp
    from scipy.optimize import root

    model = scene.model
    rest = rest_state(model)
    gravity = np.zeros((model.n_links, 6))
    gravity[:, :3] = np.asarray(model.masses)[:, None] * scene.gravity

    def state_of(q):
        q = q.reshape(-1, 6)
        positions = rest.positions.copy()
        rotations = rest.rotations.copy()
        positions[1:] += q[:, :3]
        rotations[1:] = so3_exp(q[:, 3:]) @ rotations[1:]
        return ChainState(positions, rotations)

    def residual(q, load):
        state = state_of(q)
        return (internal_wrenches(model, state) + gravity + load(state)).reshape(-1)

    # load stepping (continuation in the actuation) from rest, each step from the last root
    q = np.zeros(6 * model.n_links)
    for fraction in np.linspace(0.1, 1.0, 10):
        load, _ = actuator_loads(scene.actuators, fraction * np.asarray(actuation))
        q = root(residual, q, args=(load,), method='hybr', options={'xtol': 1e-12}).x
    # judged by its residual (MINPACK may report slow progress once at round-off)
    assert np.linalg.norm(residual(q, load)) < 1e-8
    return state_of(q).positions


@pytest.mark.parametrize('scene_name, actuation', [
    ('tendon_6f_8c', [3.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0]),
    ('cbha', [1e5, 2e4, 0.0, 5e4, 0.0, 1e5]),
])
def test_plant_reaches_the_equilibrium_of_an_independent_root_solve(scene_name, actuation):
    """Warm-started Newton from rest = MINPACK's root of the same residual (softer, gravity)."""
    scene = load_scene(scene_name, stiffness_scale=0.9)
    reference = _root_reference(scene, actuation)
    plant = StaticPlant(scene, tolerance=1e-9)
    result = plant.update(actuation)
    assert result.converged
    np.testing.assert_allclose(result.positions, reference, atol=1e-7)
    # the actuation moves the tip frame by > 5 mm, far more than the 0.1 um tolerance
    from cbha_inverse.core.chain import rest_state
    assert np.abs(reference - rest_state(scene.model).positions).max() > 5e-3
    # warm start: a small change converges in a few iterations from the previous equilibrium
    nudged = np.asarray(actuation) * 0.98
    again = plant.update(nudged)
    assert again.converged and again.iterations < result.iterations
    np.testing.assert_allclose(again.positions, _root_reference(scene, nudged), atol=1e-7)


def test_tracking_errors_against_interpolated_targets():
    times = np.linspace(0.0, 10.0, 1001)
    targets = np.stack([np.zeros_like(times), np.cos(times), np.sin(times)], axis=1)
    tip_times = np.linspace(0.0, 10.0, 337)
    tips = np.stack([np.zeros_like(tip_times), np.cos(tip_times), np.sin(tip_times)], axis=1)
    tips[:, 0] += 0.002  # constant 2 mm offset along x
    errors = tracking_errors(times, targets, tip_times, tips, 2.0, 8.0)
    assert errors.times.min() >= 2.0 and errors.times.max() <= 8.0
    assert errors.rms == pytest.approx(0.002, abs=1e-4)
    assert errors.maximum == pytest.approx(0.002, abs=1e-4)
    with pytest.raises(ValueError, match='no tip sample'):
        tracking_errors(times, targets, tip_times, tips, 20.0, 30.0)


def test_the_unblocked_part_leaves_out_blocked_targets_and_the_settling():
    """
    A target line through a ball: blocked while closer than the distance, then settling.

    Targets x = -1 + 0.2 t [m] pass a ball of radius 0.1 at the origin; with distance 0.05 they
    are blocked for |x| < 0.15, i.e. 4.25 < t < 5.75 s, and the ~0.5 s after are settling.
    """
    times = np.linspace(0.0, 10.0, 1001)
    goals = np.stack([-1.0 + 0.2 * times, np.zeros_like(times), np.zeros_like(times)], axis=1)
    tips = goals + [0.0, 0.001, 0.0]
    out = (times > 4.25) & (times < 6.25)
    tips[out, 1] = 0.05         # held off the target: 50 mm
    tracking = tracking_errors(times, goals, times, tips, 0.0, 10.0)
    np.testing.assert_allclose(tracking.goals, goals, atol=1e-15)
    ball = Obstacle('ball', 'sphere', [0.0, 0.0, 0.0], np.eye(3), radius=0.1)
    unblocked, kept = unblocked_errors(tracking, [ball], 0.05, 0.505)   # (off the 10 ms grid)
    gap = np.abs(goals[:, 0]) - 0.1
    last_blocked = times[gap < 0.05].max()
    assert last_blocked == pytest.approx(5.74)
    np.testing.assert_array_equal(kept, (gap >= 0.05) & ~((times > last_blocked)
                                                          & (times <= last_blocked + 0.505)))
    assert unblocked.rms == pytest.approx(0.001, rel=1e-9)
    assert unblocked.maximum == pytest.approx(0.001, rel=1e-9)
    assert tracking.maximum == pytest.approx(0.05)
    with pytest.raises(ValueError, match='every sample'):
        unblocked_errors(tracking, [ball], 2.0, 0.5)


def test_plot_runs_writes_a_png(tmp_path):
    circle = np.stack([np.zeros(50), np.cos(np.linspace(0, 6.3, 50)),
                       np.sin(np.linspace(0, 6.3, 50))], axis=1) * 0.06
    path = tmp_path / 'demo.png'
    plot_runs([{'title': 'circle open loop', 'targets': circle, 'tips': circle * 1.01,
                'rms': 6e-4}], path)
    assert path.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
