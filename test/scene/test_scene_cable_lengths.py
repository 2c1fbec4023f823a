"""Tendon lengths at a pose (``Scene.cable_lengths``) against closed forms and differences."""

from cbha_inverse.core._kernels.retraction import retract_frames
from cbha_inverse.core.chain import ChainState
from cbha_inverse.core.so3 import so3_exp
from cbha_inverse.paths import config_path
from cbha_inverse.scene import load_scene
import numpy as np
import pytest


@pytest.fixture(scope='module')
def scene():
    return load_scene(config_path('scenes', 'tendon_6f_8c.yaml'))


@pytest.fixture(scope='module')
def arc_lengths(scene):
    """Return the frames' distance from the base along the straight rest backbone [m]."""
    no_gravity = load_scene(config_path('scenes', 'tendon_6f_8c.yaml'), gravity=[0.0, 0.0, 0.0])
    positions = no_gravity.forward(np.zeros(len(scene.actuator_names)),
                                   strict=True).state.positions
    np.testing.assert_allclose(positions[:, 1:], 0.0, atol=1e-12)
    return positions[:, 0]


def _arc_state(arc_lengths, bend, direction):
    """
    Bend the backbone on a circular arc of total angle ``bend`` toward ``direction`` (⊥ +x).

    Every frame origin keeps its arc length from the base and turns with the arc's tangent.
    Returns the state, each frame's angle on the arc and the arc's radius [m].
    """
    radius = arc_lengths[-1] / bend
    angle = arc_lengths / radius
    x, u = np.array([1.0, 0.0, 0.0]), np.asarray(direction, dtype=float)
    positions = radius * (np.sin(angle)[:, None] * x + (1.0 - np.cos(angle))[:, None] * u)
    axis = np.cross(x, u)
    rotations = np.stack([so3_exp(a * axis) for a in angle])
    return ChainState(positions, rotations), angle, radius


@pytest.mark.parametrize('bend', [1e-3, 0.3, 1.2])
def test_a_tendon_on_an_arc_is_the_chord_polygon_of_its_offset_circle(scene, arc_lengths, bend):
    """
    Compare each tendon on arcs of radius R with its chords and the continuous arc's -r θ.

    A routing point at offset r toward the centre of curvature lies on the circle of radius
    R - r: the routed length is the sum of its chords, and its change against the backbone's own
    chords is -r θ up to the second order of the spans' angles.
    """
    straight_state = _arc_state(arc_lengths, 1e-12, [0.0, 1.0, 0.0])[0]
    names, straight, _ = scene.cable_lengths(straight_state)
    group = scene.tendon_routes.group
    for index, cable in enumerate(group.cables):
        r = float(np.linalg.norm(cable.offsets[0]))
        np.testing.assert_allclose(cable.offsets[:, 0], 0.0, atol=1e-15)
        np.testing.assert_allclose(np.linalg.norm(cable.offsets, axis=1), r, rtol=1e-12)
        direction = np.array([0.0, *cable.offsets[0, 1:]]) / r
        state, angle, radius = _arc_state(arc_lengths, bend, direction)
        _, lengths, _ = scene.cable_lengths(state)
        spans = np.diff(angle[cable.frames])
        chords = 2.0 * (radius - r) * np.sin(spans / 2.0)
        assert lengths[index] == pytest.approx(chords.sum(), rel=1e-12)
        # against the backbone's own polygon through the same frames (r = 0), the change is
        # -r θ of a continuous arc (θ the routed part's bend) up to the chords' dφ² / 24
        backbone = 2.0 * radius * np.sin(spans / 2.0)
        theta = angle[cable.frames[-1]]
        change = lengths[index] - backbone.sum() - (straight[index] - np.diff(
            arc_lengths[cable.frames]).sum())
        assert change == pytest.approx(-r * theta, rel=spans.max() ** 2 / 24.0 + 1e-9)
    assert names == tuple(n for n in scene.actuator_names)


def test_the_length_gradient_is_its_finite_difference(scene):
    """``d(length)/dq`` against central differences of the lengths along random increments."""
    state = scene.forward(np.linspace(0.0, 6.0, len(scene.actuator_names)), strict=True).state
    _, lengths, jacobian = scene.cable_lengths(state)
    rng = np.random.default_rng(5)
    for _ in range(3):
        step = rng.normal(size=jacobian.shape[1]) * 1e-6
        moved = []
        for sign in (1.0, -1.0):
            positions, rotations = state.positions.copy(), state.rotations.copy()
            retract_frames(positions, rotations, (sign * step).reshape(-1, 6), in_place=True)
            moved.append(scene.cable_lengths(ChainState(positions, rotations))[1])
        np.testing.assert_allclose((moved[0] - moved[1]) / 2.0, jacobian @ step, rtol=1e-6,
                                   atol=1e-15)


def test_a_scene_without_cables_says_so():
    cbha = load_scene(config_path('scenes', 'cbha.yaml'))
    with pytest.raises(ValueError, match='no cable'):
        cbha.cable_lengths(cbha.forward(np.zeros(6), strict=True).state)
