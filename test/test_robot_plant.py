"""The pure parts behind cbha_sim and cbha_demo: the plant and the tracking metrics."""

from cbha_inverse.report.tracking import plot_runs, tracking_errors
from cbha_inverse.robot.plant import StaticPlant
from cbha_inverse.scene import load_scene
import numpy as np
import pytest


@pytest.mark.parametrize('scene_name, actuation', [
    ('tendon_6f_8c', [3.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0]),
    ('cbha', [1e5, 2e4, 0.0, 5e4, 0.0, 1e5]),
])
def test_plant_reaches_the_scene_forward_equilibrium(scene_name, actuation):
    """Warm-started Newton from rest = the scene's own static solve (softer model, gravity)."""
    scene = load_scene(scene_name, stiffness_scale=0.9)
    reference = scene.forward(actuation)
    plant = StaticPlant(scene, tolerance=1e-9)
    result = plant.update(actuation)
    assert reference.converged and result.converged
    np.testing.assert_allclose(result.positions, reference.positions, atol=1e-7)
    # warm start: a small change converges in a few iterations from the previous equilibrium
    nudged = np.asarray(actuation) * 0.98
    again = plant.update(nudged)
    assert again.converged and again.iterations < result.iterations
    np.testing.assert_allclose(again.effector_positions,
                               scene.forward(nudged).effector_positions, atol=1e-7)


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


def test_plot_runs_writes_a_png(tmp_path):
    circle = np.stack([np.zeros(50), np.cos(np.linspace(0, 6.3, 50)),
                       np.sin(np.linspace(0, 6.3, 50))], axis=1) * 0.06
    path = tmp_path / 'demo.png'
    plot_runs([{'title': 'circle open loop', 'targets': circle, 'tips': circle * 1.01,
                'rms': 6e-4}], path)
    assert path.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
