"""String potentiometers: lengths against closed forms, the Jacobian against finite differences."""

from cbha_inverse.core.actuation.cables import Cable, CableGroup
from cbha_inverse.core.chain import ChainModel, rest_state, retract
from cbha_inverse.core.links import timoshenko_compliance
from cbha_inverse.core.sensors import StringPots
from cbha_inverse.core.so3 import so3_exp
import numpy as np
from oracles.actuation import oracle
import pytest

N_LINKS = 6
LENGTH = 0.0125
RADIUS = 0.014


def _model():
    c = timoshenko_compliance(LENGTH, 2e7, 0.45, 0.006)
    return ChainModel.from_compliances(np.broadcast_to(c, (N_LINKS, 6, 6)),
                                       np.tile([LENGTH, 0.0, 0.0], (N_LINKS, 1)))


def _offsets(angle_deg, end):
    """Routing points at RADIUS and the angle (from +y toward +z) on frames 0..end."""
    angle = np.deg2rad(angle_deg)
    return np.tile([0.0, RADIUS * np.cos(angle), RADIUS * np.sin(angle)], (end + 1, 1))


def _pots(angles_deg, end=N_LINKS, gain=1000.0, offset=0.0):
    """Pots through every frame from the base to ``end``, at RADIUS and the given angles."""
    return StringPots([f'pot_{a:g}' for a in angles_deg], [np.arange(end + 1)] * len(angles_deg),
                      [_offsets(a, end) for a in angles_deg], N_LINKS + 1, offset, gain, 1e-4)


def _arc(curvature):
    """Frames on a constant-curvature arc bending toward +z (about -y), unit arc step."""
    angles = curvature * LENGTH * np.arange(N_LINKS + 1)
    positions = np.stack([np.sin(angles) / curvature, np.zeros_like(angles),
                          (1.0 - np.cos(angles)) / curvature], axis=1)
    rotations = np.stack([so3_exp(np.array([0.0, -a, 0.0])) for a in angles])
    return positions, rotations


def test_straight_arm_lengths_are_the_section_lengths():
    pots = _pots([90.0, 210.0, 330.0])
    state = rest_state(_model())
    np.testing.assert_allclose(pots.lengths(state.positions, state.rotations),
                               N_LINKS * LENGTH, rtol=1e-14)


@pytest.mark.parametrize('curvature', [2.0, 8.0, -5.0])
def test_constant_curvature_lengths_are_chords_of_the_offset_arc(curvature):
    angles = np.array([90.0, 210.0, 330.0, 0.0])
    pots = _pots(angles)
    positions, rotations = _arc(curvature)
    # a point at height z = r sin(angle) above the backbone lies on the arc of radius 1/κ - z:
    # N chords of 2 (1/κ - z) sin(κ h / 2)
    z = RADIUS * np.sin(np.deg2rad(angles))
    expected = N_LINKS * 2.0 * (1.0 / curvature - z) * np.sin(curvature * LENGTH / 2.0)
    np.testing.assert_allclose(pots.lengths(positions, rotations), expected, rtol=1e-12)
    # the over pot (+z, inside the bend for κ > 0) shortens, the side pots lengthen
    assert (pots.lengths(positions, rotations)[0] < N_LINKS * LENGTH) == (curvature > 0)


def test_lengths_equal_the_routed_length_of_the_cable_oracle():
    pots = _pots([90.0, 250.0], end=4)
    rng = np.random.default_rng(3)
    state = retract(rest_state(_model()), 0.05 * rng.standard_normal((N_LINKS, 6)))
    group = CableGroup([Cable(name, np.arange(5), _offsets(angle, 4))
                        for name, angle in zip(pots.names, (90.0, 250.0))], N_LINKS + 1)
    np.testing.assert_allclose(pots.lengths(state.positions, state.rotations),
                               oracle(group).lengths(state.positions, state.rotations),
                               rtol=1e-13)


def test_jacobian_matches_finite_differences():
    pots = _pots([90.0, 210.0, 330.0], end=4)
    rng = np.random.default_rng(7)
    state = retract(rest_state(_model()), 0.1 * rng.standard_normal((N_LINKS, 6)))
    _, jacobian = pots.lengths_and_jacobian(state.positions, state.rotations)
    jacobian = jacobian.copy()
    h = 1e-6
    for _ in range(4):
        dq = rng.standard_normal((N_LINKS, 6)) * [0.01, 0.01, 0.01, 1, 1, 1]
        plus = retract(state, h * dq)
        minus = retract(state, -h * dq)
        fd = (pots.lengths(plus.positions, plus.rotations)
              - pots.lengths(minus.positions, minus.rotations)) / (2 * h)
        np.testing.assert_allclose(jacobian @ dq.reshape(-1), fd, rtol=1e-6, atol=1e-10)
    # frames beyond the end of the routing do not move the length
    assert not jacobian[:, 6 * 4:].any()


def test_readings_are_affine_and_invert():
    pots = _pots([90.0, 210.0], gain=[1000.0, -500.0], offset=[3.0, 120.0])
    lengths = np.array([0.1, 0.2])
    np.testing.assert_allclose(pots.readings(lengths), [103.0, 20.0])
    np.testing.assert_allclose(pots.lengths_of(pots.readings(lengths)), lengths)
    other = pots.recalibrated(reading_offset=[0.0, 0.0])
    np.testing.assert_allclose(other.readings(lengths), [100.0, -100.0])
    np.testing.assert_allclose(pots.reading_offset, [3.0, 120.0])


@pytest.mark.parametrize('kwargs, match', [
    ({'reading_gain': 0.0}, 'gain'), ({'noise_std': 0.0}, 'noise_std'),
    ({'reading_offset': np.nan}, 'offset')])
def test_bad_calibration_is_refused(kwargs, match):
    args = {'reading_offset': 0.0, 'reading_gain': 1.0, 'noise_std': 1e-4, **kwargs}
    with pytest.raises(ValueError, match=match):
        StringPots(['a'], [[0, 1]], [[[0, 0, 0.01]] * 2], N_LINKS + 1, **args)


def test_a_frame_outside_the_chain_is_refused():
    with pytest.raises(ValueError, match='outside'):
        StringPots(['a'], [[0, N_LINKS + 1]], [[[0, 0, 0.01]] * 2], N_LINKS + 1, 0.0, 1.0, 1e-4)
