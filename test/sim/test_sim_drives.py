"""The simulated plant driven by tendon displacements (position-controlled drives)."""

from cbha_inverse.scene import load_scene
from cbha_inverse.sim.plant import StaticPlant
import numpy as np
import pytest

TENSIONS = np.array([3.0, 0.0, 0.0, 1.5, 0.0, 2.0, 0.0, 0.5])


def test_a_displacement_plant_follows_a_ramp_to_the_pose_of_the_tensions():
    """Warm-started updates along a ramp of displacements: at its end the pose of the tensions."""
    scene = load_scene('tendon_6f_8c')
    by_tension = scene.forward(TENSIONS, strict=True)
    target = scene.tendon_drives.displacements(by_tension.state, TENSIONS)
    plant = StaticPlant(scene, tolerance=1e-9, command_kind='displacement')
    for fraction in np.linspace(0.1, 1.0, 10):
        result = plant.update(fraction * target)
        assert result.converged, result.message
    np.testing.assert_allclose(result.effector_positions, by_tension.effector_positions,
                               atol=1e-8)
    np.testing.assert_allclose(plant.tensions, TENSIONS, atol=1e-5)
    plant.reset()
    np.testing.assert_array_equal(plant.tensions, 0.0)


def test_a_plant_without_displacement_drives_says_so():
    with pytest.raises(ValueError, match='finite axial_stiffness'):
        StaticPlant(load_scene('cbha'), command_kind='displacement')
    with pytest.raises(ValueError, match='command_kind'):
        StaticPlant(load_scene('tendon_6f_8c'), command_kind='position')
