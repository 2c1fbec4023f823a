"""The simulated plant against obstacles: penalty contact, its reaction, and no change without."""

from cbha_inverse.core.obstacles import Obstacle
from cbha_inverse.core.statics import solve_static
from cbha_inverse.scene import load_scene
from cbha_inverse.sim.plant import StaticPlant
import numpy as np
import pytest
from scipy.optimize import brentq

# tendon_6f_8c with its tip tendon below the backbone pulled: the tip bends down to z = -21 mm
_PULL_DOWN = [0.0, 0.0, 0.0, 4.0, 0.0, 0.0, 0.0, 0.0]
_TABLE = Obstacle('table', 'plane', [0.0, 0.0, -0.015], np.eye(3))


def _free_tip_height(scene, force):
    """Return the tip frame's height under the pull and an upward tip force (no contact)."""
    tip_wrench = np.array([0.0, 0.0, force, 0.0, 0.0, 0.0])
    result = solve_static(scene.model, tip_wrench, gravity=scene.gravity,
                          actuators=scene.actuators, actuation=_PULL_DOWN, strict=True,
                          check_warnings=False)
    return result.positions[-1, 2]


@pytest.fixture(scope='module')
def tendon():
    return load_scene('tendon_6f_8c')


def test_contact_force_is_the_reaction_the_free_solve_predicts(tendon):
    """
    The tip pressed onto a table: its penalty force is the force that holds it on the table.

    Reference: the free solve (no obstacle) with an upward dead force at the tip, whose
    magnitude is found by root finding so that the tip's sphere just touches the table: the
    table's reaction. The penalty's equilibrium penetrates by force / stiffness.
    """
    radius = tendon.collision.radii[-1]
    reaction = brentq(lambda f: _free_tip_height(tendon, f) - radius - _TABLE.position[2],
                      0.0, 2.0, xtol=1e-12)
    free = _free_tip_height(tendon, 0.0)
    assert free - radius < _TABLE.position[2] - 0.01     # unobstructed, 1 cm into the table
    for stiffness, tolerance in ((1e4, 5e-3), (1e5, 5e-4)):
        plant = StaticPlant(tendon, tolerance=1e-10, contact_stiffness=stiffness)
        plant.set_obstacles([_TABLE])
        result = plant.update(_PULL_DOWN)
        assert result.converged and result.iterations <= 6
        contacts = plant.contacts
        assert contacts.frames.tolist() == [tendon.model.n_links]   # the tip alone
        force = contacts.forces[0]
        np.testing.assert_allclose(force[:2], 0.0, atol=1e-12)       # frictionless: normal
        assert force[2] == pytest.approx(reaction, rel=tolerance)
        # the penetration is the force over the penalty stiffness, a few micrometres
        assert contacts.penetrations[0] == pytest.approx(force[2] / stiffness, rel=1e-9)
        assert contacts.penetrations[0] <= 1.01 * reaction / stiffness
        assert result.positions[-1, 2] - radius == pytest.approx(
            _TABLE.position[2] - contacts.penetrations[0], abs=1e-12)
        np.testing.assert_allclose(contacts.points[0], [*result.positions[-1, :2], -0.015],
                                   atol=1e-12)


def test_a_controller_that_ignores_an_obstacle_presses_into_it(tendon):
    """
    The inverse model (no obstacle) reaches a target 8 mm below a table; the plant stops on it.

    The command that puts the free tip on the target leaves the plant's tip on the table, the
    target missed by about the table's depth, the tip sphere pressed in by its force over the
    stiffness.
    """
    solver = tendon.make_inverse_solver()
    target = tendon.forward(_PULL_DOWN).effector_positions[-1]     # reachable: 21 mm down
    for _ in range(60):
        step = solver.step(target[None, :])
    assert np.linalg.norm(step.effector_positions[-1] - target) < 1e-4
    radius = tendon.collision.radii[-1]
    table = Obstacle('table', 'plane', [0.0, 0.0, target[2] - radius + 0.008], np.eye(3))
    plant = StaticPlant(tendon, tolerance=1e-10, contact_stiffness=1e4)
    plant.set_obstacles([table])
    free = StaticPlant(tendon, tolerance=1e-10).update(step.actuation)
    pressed = plant.update(step.actuation)
    assert pressed.converged
    assert np.linalg.norm(free.effector_positions[-1] - target) < 1e-4
    contacts = plant.contacts
    assert tendon.model.n_links in contacts.frames.tolist()
    tip_force = contacts.forces[contacts.frames == tendon.model.n_links][0]
    assert tip_force[2] > 0.05    # N: it presses
    depth = contacts.penetrations[contacts.frames == tendon.model.n_links][0]
    assert depth == pytest.approx(tip_force[2] / 1e4, rel=1e-9)
    miss = pressed.effector_positions[-1, 2] - target[2]
    assert miss == pytest.approx(0.008 - depth, abs=1e-12)


def test_without_obstacles_the_plant_is_unchanged_bit_for_bit(tendon):
    """No obstacle: the plant's solve is solve_static's, bit for bit; far ones change nothing."""
    plant = StaticPlant(tendon, tolerance=1e-9)
    result = plant.update(_PULL_DOWN)
    reference = solve_static(tendon.model, gravity=tendon.gravity, actuators=tendon.actuators,
                             actuation=_PULL_DOWN, effectors=tendon.effectors,
                             absolute_tolerance=1e-9, max_iterations=20, max_load_steps=16,
                             check_warnings=False)
    assert np.array_equal(result.positions, reference.positions)
    assert np.array_equal(result.rotations, reference.rotations)
    assert plant.contacts.frames.size == 0
    far = StaticPlant(tendon, tolerance=1e-9)
    far.set_obstacles([Obstacle('far', 'sphere', [0.0, 1.0, 0.0], np.eye(3), radius=0.1)])
    distant = far.update(_PULL_DOWN)
    np.testing.assert_allclose(distant.positions, reference.positions, atol=1e-12)
    assert far.contacts.frames.size == 0
    # removed again: back on the path without contact
    far.set_obstacles([])
    far.reset()
    assert np.array_equal(far.update(_PULL_DOWN).positions, reference.positions)


def test_the_cbha_rests_on_a_curved_obstacle_with_quadratic_newton():
    """The CBHA's drooping tip on a sphere: converges in few iterations, force along the normal."""
    cbha = load_scene('cbha')
    plant = StaticPlant(cbha, tolerance=1e-8, contact_stiffness=1e4)
    tip = cbha.rest_effector_positions[-1]
    ball = Obstacle('ball', 'sphere', tip + [0.004, 0.01, -0.05], np.eye(3), radius=0.03)
    plant.set_obstacles([ball])
    result = plant.update(np.zeros(6))
    assert result.converged and result.iterations <= 10
    contacts = plant.contacts
    assert contacts.frames.size >= 1
    centres = result.positions[contacts.frames]
    outward = (centres - ball.position) / np.linalg.norm(centres - ball.position, axis=1)[:, None]
    np.testing.assert_allclose(contacts.normals, outward, atol=1e-12)
    np.testing.assert_allclose(np.cross(contacts.forces, outward), 0.0, atol=1e-12)
    # the arm's weight beyond the contact is held: the normal forces are upward
    assert contacts.forces[:, 2].sum() > 0.0


def test_the_plant_reports_its_clearance_as_the_closed_form_gap():
    """
    The plant's clearance is the smallest gap of its spheres, by the closed forms of the shapes.

    A table below the drooping CBHA: ``z - h - ρ`` of every sphere centre; a ball beside it:
    ``|x - c| - R - ρ``. The table raised into the arm: the clearance is minus the deepest
    contact's penetration.
    """
    cbha = load_scene('cbha_post')
    radius = cbha.collision.radii[0]
    plant = StaticPlant(cbha, tolerance=1e-8, contact_stiffness=1e4)
    assert plant.clearance == np.inf
    ball_centre = np.array([0.1, 0.09, 0.0])
    plant.set_obstacles([Obstacle('table', 'plane', [0.0, 0.0, -0.2], np.eye(3)),
                         Obstacle('ball', 'sphere', ball_centre, np.eye(3), radius=0.03)])
    result = plant.update(np.zeros(6))
    centres = result.positions[1:]
    above_table = centres[:, 2] + 0.2 - radius
    beside_ball = np.linalg.norm(centres - ball_centre, axis=1) - 0.03 - radius
    assert plant.contacts.frames.size == 0
    assert plant.clearance == pytest.approx(min(above_table.min(), beside_ball.min()), abs=1e-15)
    plant.set_obstacles([Obstacle('table', 'plane', [0.0, 0.0, -0.03], np.eye(3))])
    result = plant.update(np.zeros(6))
    assert plant.contacts.frames.size >= 1
    assert plant.clearance == pytest.approx(-plant.contacts.penetrations.max(), abs=1e-15)
    assert plant.clearance == pytest.approx(result.positions[1:, 2].min() + 0.03 - radius,
                                            abs=1e-15)
    plant.set_obstacles([])
    plant.update(np.zeros(6))
    assert plant.clearance == np.inf
