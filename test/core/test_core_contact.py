"""Tests of the penalty contact: its loads, their exact tangent, the step limit, the report."""

from cbha_inverse.core.chain import ChainModel, ChainState, rest_state
from cbha_inverse.core.contact import CollisionSpheres, PenaltyContact, TOUCH_MARGIN
from cbha_inverse.core.obstacles import Obstacle
from cbha_inverse.core.so3 import so3_exp
import numpy as np
import pytest


def _chain(n=4):
    """Return a straight chain of ``n`` 20 mm links along +x (stiffness irrelevant here)."""
    compliance = np.diag([1e-6, 1e-4, 1e-4, 1e-2, 1e-1, 1e-1])
    return ChainModel.from_compliances(np.broadcast_to(compliance, (n, 6, 6)),
                                       np.tile([0.02, 0.0, 0.0], (n, 1)))


def _state(model, rng, scale=0.01):
    """Return the rest shape with random displacements and turns of frames 1..n."""
    rest = rest_state(model)
    positions = rest.positions.copy()
    positions[1:] += rng.normal(scale=scale, size=(model.n_links, 3))
    rotations = rest.rotations.copy()
    rotations[1:] = so3_exp(rng.normal(scale=0.2, size=(model.n_links, 3))) @ rotations[1:]
    return ChainState(positions, rotations)


def _obstacles():
    """Return a sphere near frames 2-3, a turned box the tip enters by an edge, a floor."""
    turn = so3_exp(np.array([0.2, -0.4, 0.7]))
    return [Obstacle('ball', 'sphere', [0.05, 0.0, -0.028], np.eye(3), radius=0.02),
            Obstacle('crate', 'box', [0.1, 0.015, 0.012], turn, size=(0.03, 0.02, 0.04)),
            Obstacle('floor', 'plane', [0.0, 0.0, -0.008], np.eye(3))]


def test_tangent_is_minus_the_derivative_of_the_contact_wrenches():
    """Central differences of the wrenches (world-axis increments) give -tangent."""
    model = _chain()
    contact = PenaltyContact(CollisionSpheres([1, 2, 3, 4], [0.006, 0.007, 0.008, 0.009]),
                             _obstacles(), 3e4, model.n_links)
    rng = np.random.default_rng(5)
    checked = 0
    for _ in range(20):
        state = _state(model, rng)
        tangent = contact.tangent(state)
        step = 1e-8
        numeric = np.zeros_like(tangent)
        for column in range(6 * model.n_links):
            shift = np.zeros(6 * model.n_links)
            shift[column] = step
            ahead = _retracted(state, shift)
            behind = _retracted(state, -shift)
            if (_touching(contact, ahead) != _touching(contact, behind)
                    or _touching(contact, ahead) != _touching(contact, state)):
                break    # a contact begins or ends inside the stencil: no reference
            numeric[:, column] = -(contact.wrenches(ahead) - contact.wrenches(behind)).reshape(
                -1) / (2 * step)
        else:
            np.testing.assert_allclose(tangent, numeric, atol=1e-4 * 3e4 * 1e-3 + 1e-3)
            checked += bool(_touching(contact, state))
    assert checked >= 10     # most states touch something: the test compares real tangents


def test_the_loads_and_the_report_sum_every_pair_and_a_diverged_state_touches_nothing():
    """Against a loop over obstacles and spheres of ``Obstacle.signed_distance``; NaN frames."""
    model = _chain()
    spheres = CollisionSpheres([1, 2, 3, 4], [0.006, 0.007, 0.008, 0.009])
    obstacles = _obstacles()
    contact = PenaltyContact(spheres, obstacles, 3e4, model.n_links)
    rng = np.random.default_rng(9)
    pairs = 0
    for _ in range(10):
        state = _state(model, rng)
        expected, rows = np.zeros((model.n_links, 6)), []
        for obstacle in obstacles:
            query = obstacle.signed_distance(spheres.centres(state.positions))
            depth = spheres.radii - query.distance
            for s in np.flatnonzero(depth > 0.0):
                expected[spheres.frames[s] - 1, :3] += 3e4 * depth[s] * query.normal[s]
                rows.append((spheres.frames[s], obstacle.name, depth[s]))
        np.testing.assert_allclose(contact.wrenches(state), expected, rtol=1e-14, atol=1e-14)
        report = contact.contacts(state)
        assert list(zip(report.frames.tolist(), report.obstacles)) == [r[:2] for r in rows]
        np.testing.assert_allclose(report.penetrations, [r[2] for r in rows], rtol=1e-14)
        pairs += len(rows)
    assert pairs >= 10
    diverged = ChainState(np.full_like(state.positions, np.nan), state.rotations)
    assert not np.any(contact.wrenches(diverged)) and not np.any(contact.tangent(diverged))
    assert contact.contacts(diverged).frames.size == 0
    assert contact.step_limit(state, diverged) == 1.0


def _retracted(state, increments):
    """Return ``state`` with world-axis increments (n, 6) applied (as ``retract``)."""
    from cbha_inverse.core.chain import retract
    return retract(state, np.reshape(increments, (-1, 6)))


def _touching(contact, state):
    """Return the (frame, obstacle) pairs in contact at a state."""
    found = contact.contacts(state)
    return set(zip(found.frames.tolist(), found.obstacles))


def test_contact_report_of_a_sphere_on_a_floor():
    """A sphere 2 mm into a floor: penetration, normal, surface point, force k p n, no moment."""
    model = _chain(2)
    state = rest_state(model)
    floor = Obstacle('floor', 'plane', [0.0, 0.0, -0.004], np.eye(3))
    contact = PenaltyContact(CollisionSpheres([1, 2], [0.006, 0.003]), [floor], 500.0,
                             model.n_links)
    report = contact.contacts(state)
    assert report.frames.tolist() == [1] and report.obstacles == ('floor',)
    assert report.penetrations[0] == pytest.approx(0.002, abs=1e-15)
    np.testing.assert_allclose(report.normals[0], [0.0, 0.0, 1.0])
    np.testing.assert_allclose(report.points[0], [0.02, 0.0, -0.004], atol=1e-15)
    np.testing.assert_allclose(report.forces[0], [0.0, 0.0, 1.0], atol=1e-12)
    wrenches = contact.wrenches(state)
    np.testing.assert_allclose(wrenches[0], [0.0, 0.0, 1.0, 0.0, 0.0, 0.0], atol=1e-12)
    assert not np.any(wrenches[1])
    # frame 2's sphere (radius 3 mm, 1 mm above the floor) touches nothing
    assert contact.spheres.clearances(state.positions, [floor])[1, 0] == pytest.approx(0.001)


def test_step_limit_ends_the_step_where_the_first_contact_begins():
    """Along a straight path into a floor the limit is where the gap reaches -TOUCH_MARGIN."""
    model = _chain(2)
    start = rest_state(model)
    floor = Obstacle('floor', 'plane', [0.0, 0.0, -0.01], np.eye(3))
    contact = PenaltyContact(CollisionSpheres([1, 2], [0.005, 0.005]), [floor], 1e4,
                             model.n_links)
    end = ChainState(start.positions + [[0.0, 0.0, 0.0], [0.0, 0.0, -0.02], [0.0, 0.0, -0.01]],
                     start.rotations)
    # frame 1 reaches the floor after 5 mm of its 20 mm, frame 2 after 5 of 10: frame 1 first
    limit = contact.step_limit(start, end)
    assert limit == pytest.approx((0.005 + TOUCH_MARGIN) / 0.02, rel=1e-12)
    moved = ChainState(start.positions + limit * (end.positions - start.positions),
                       start.rotations)
    assert contact.spheres.clearances(moved.positions, [floor])[0, 0] == pytest.approx(
        -TOUCH_MARGIN, abs=1e-15)
    # the touching sphere's stiffness is in the tangent, its force still ~zero
    assert contact.tangent(moved)[2, 2] == pytest.approx(1e4)
    # a step that stays clear, or leaves a contact, is not shortened
    assert contact.step_limit(start, ChainState(start.positions + [0.0, 0.0, 0.001],
                                                start.rotations)) == 1.0
    assert contact.step_limit(end, start) == 1.0


@pytest.mark.parametrize('frames, radii, problem', [
    ([0, 1], [0.01, 0.01], '>= 1'),
    ([1, 1], [0.01, 0.01], 'distinct'),
    ([1, 2], [0.01, 0.0], 'radii'),
    ([1, 2], [0.01, np.nan], 'radii'),
    ([1, 2], [0.01], 'radii'),
])
def test_invalid_collision_spheres_are_refused(frames, radii, problem):
    with pytest.raises(ValueError, match=problem):
        CollisionSpheres(frames, radii)


def test_invalid_contact_parameters_are_refused():
    spheres = CollisionSpheres([1, 2], [0.01, 0.01])
    floor = Obstacle('floor', 'plane', [0.0, 0.0, 0.0], np.eye(3))
    with pytest.raises(ValueError, match='stiffness'):
        PenaltyContact(spheres, [floor], 0.0, 2)
    with pytest.raises(ValueError, match='beyond the chain'):
        PenaltyContact(spheres, [floor], 1e3, 1)
    with pytest.raises(ValueError, match='named twice'):
        PenaltyContact(spheres, [floor, floor], 1e3, 2)
