"""Tests of the SO(3) helpers against independent references (scipy Rotation, FD)."""

from cbha_inverse.core import so3
import numpy as np
from oracles import so3 as se3_oracle
import pytest
from scipy.spatial.transform import Rotation


def _rotvecs(rng, count=40):
    """Random rotation vectors incl. tiny, moderate and near-pi angles."""
    axes = rng.normal(size=(count, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.concatenate([[0.0, 1e-12, 1e-7, 1e-3, 0.0999, 0.1001, 0.5, np.pi - 1e-9,
                              np.pi - 1e-5, 3.0], rng.uniform(0, np.pi, count - 10)])
    return axes * angles[:, None]


def test_hat_vee_cross():
    """hat(a) b equals a x b and vee inverts hat."""
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(2, 5, 3))
    np.testing.assert_allclose((so3.hat(a) @ b[..., None])[..., 0], np.cross(a, b), atol=1e-15)
    np.testing.assert_allclose(so3.vee(so3.hat(a)), a, atol=0)


def test_exp_log_against_scipy():
    """so3_exp matches scipy's Rotation and so3_log inverts it at every angle."""
    rng = np.random.default_rng(1)
    v = _rotvecs(rng)
    rot = so3.so3_exp(v)
    np.testing.assert_allclose(rot, Rotation.from_rotvec(v).as_matrix(), atol=1e-14)
    back = so3.so3_log(rot)
    np.testing.assert_allclose(so3.so3_exp(back), rot, atol=1e-14)
    far = np.linalg.norm(v, axis=1) < np.pi - 1e-4
    np.testing.assert_allclose(back[far], v[far], atol=1e-14, rtol=1e-12)


def test_rpy_against_scipy_and_back_through_gimbal_lock():
    """``Rz(yaw) Ry(pitch) Rx(roll)`` is scipy's extrinsic 'xyz'; the inverse gives the angles."""
    rng = np.random.default_rng(4)
    rpy = rng.uniform(-np.pi, np.pi, (60, 3))
    rpy[:, 1] = rng.uniform(-0.5 * np.pi, 0.5 * np.pi, 60)
    rot = so3.so3_from_rpy(rpy)
    np.testing.assert_allclose(rot, Rotation.from_euler('xyz', rpy).as_matrix(), atol=1e-15)
    np.testing.assert_allclose(so3.rpy_from_so3(rot), rpy, atol=1e-13)
    assert so3.so3_from_rpy(rpy.reshape(3, 20, 3)).shape == (3, 20, 3, 3)
    # at pitch +-pi/2 only yaw -+ roll is defined: roll 0, the matrix is reproduced
    locked = np.array([[0.3, 0.5 * np.pi, -0.7], [0.3, -0.5 * np.pi, -0.7],
                       [0.3, 0.5 * np.pi - 1e-10, -0.7]])
    back = so3.rpy_from_so3(so3.so3_from_rpy(locked))
    np.testing.assert_array_equal(back[:, 0], 0.0)
    np.testing.assert_allclose(so3.so3_from_rpy(back), so3.so3_from_rpy(locked), atol=1e-9)
    np.testing.assert_allclose(back[:2, 2], [-1.0, -0.4], atol=1e-14)


def test_log_at_pi():
    """A rotation by exactly pi returns angle pi about the right axis (sign free)."""
    axis = np.array([1.0, 2.0, -2.0]) / 3.0
    rot = 2.0 * np.outer(axis, axis) - np.eye(3)
    v = so3.so3_log(rot)
    assert np.linalg.norm(v) == pytest.approx(np.pi, abs=1e-12)
    np.testing.assert_allclose(np.abs(v / np.pi), np.abs(axis), atol=1e-12)


def test_quaternions_against_scipy():
    """Quaternions are (x, y, z, w) like scipy's, w >= 0, and round-trip."""
    rng = np.random.default_rng(2)
    rot = Rotation.random(50, random_state=3).as_matrix()
    q = so3.quat_from_matrix(rot)
    ref = Rotation.from_matrix(rot).as_quat()
    ref = np.where(ref[:, 3:] < 0, -ref, ref)
    np.testing.assert_allclose(q, ref, atol=1e-14)
    np.testing.assert_allclose(so3.matrix_from_quat(q), rot, atol=1e-14)
    v = _rotvecs(rng)
    np.testing.assert_allclose(so3.matrix_from_quat(so3.quat_from_matrix(so3.so3_exp(v))),
                               so3.so3_exp(v), atol=1e-14)


def test_pose_vectors_closed_form_axis_angle_quaternion():
    """A rotation by t about the unit axis u is (u sin(t/2), cos(t/2)); batched over frames."""
    axes = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [2.0, -1.0, 2.0]]) / [[1.0], [1.0], [3.0]]
    angles = np.array([0.3, 2.5, 3.1])
    rotations = []
    for u, t in zip(axes, angles):
        # Rodrigues' formula written out: R = cos t I + sin t [u]x + (1 - cos t) u u^T
        cross = np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])
        rotations.append(np.cos(t) * np.eye(3) + np.sin(t) * cross
                         + (1.0 - np.cos(t)) * np.outer(u, u))
    translations = np.array([[0.1, 0.2, 0.3], [-1.0, 0.0, 2.0], [0.0, 0.0, 0.0]])
    poses = so3.pose_vector(np.array(rotations), translations)
    assert poses.shape == (3, 7)
    np.testing.assert_array_equal(poses[:, :3], translations)
    np.testing.assert_allclose(poses[:, 3:6], axes * np.sin(angles / 2)[:, None], atol=1e-15)
    np.testing.assert_allclose(poses[:, 6], np.cos(angles / 2), atol=1e-15)
    # a half turn about z: (0, 0, 1, 0); one pose alone is (7,)
    np.testing.assert_allclose(so3.pose_vector(np.diag([-1.0, -1.0, 1.0]), [1.0, 2.0, 3.0]),
                               [1.0, 2.0, 3.0, 0.0, 0.0, 1.0, 0.0], atol=1e-15)


@pytest.mark.parametrize('angle', [0.0, 1e-6, 0.05, 0.3, 0.7, 2.0, 3.0])
def test_left_jacobian_inverse_and_derivative(angle):
    """Jl^-1 linearises log(exp(e) exp(phi)); its transpose derivative matches central FD."""
    rng = np.random.default_rng(4)
    axis = rng.normal(size=3)
    phi = axis / np.linalg.norm(axis) * angle
    jinv = so3.so3_left_jacobian_inverse(phi)
    h = 1e-6
    fd = np.stack([(so3.so3_log(so3.so3_exp(h * e) @ so3.so3_exp(phi))
                    - so3.so3_log(so3.so3_exp(-h * e) @ so3.so3_exp(phi))) / (2 * h)
                   for e in np.eye(3)], axis=-1)
    np.testing.assert_allclose(jinv, fd, atol=1e-8)
    s = rng.normal(size=3)
    d = se3_oracle.so3_left_jacobian_inverse_transpose_derivative(phi, s)
    h = 1e-5
    fd = np.stack([(so3.so3_left_jacobian_inverse(phi + h * e).T @ s
                    - so3.so3_left_jacobian_inverse(phi - h * e).T @ s) / (2 * h)
                   for e in np.eye(3)], axis=-1)
    np.testing.assert_allclose(d, fd, atol=1e-9)


def test_slerp_against_scipy():
    """so3_slerp is scipy's Slerp (quaternion slerp, the short way) at every fraction."""
    from scipy.spatial.transform import Slerp
    rng = np.random.default_rng(5)
    pairs = Rotation.from_rotvec(_rotvecs(rng, 24)), Rotation.from_rotvec(_rotvecs(rng, 24))
    fractions = np.array([0.0, 0.1, 0.5, 0.73, 1.0])
    for r0, r1 in zip(*pairs):
        reference = Slerp([0.0, 1.0], Rotation.concatenate([r0, r1]))(fractions).as_matrix()
        ours = so3.so3_slerp(r0.as_matrix(), r1.as_matrix(), fractions)
        np.testing.assert_allclose(ours, reference, atol=1e-12)


def test_shortest_rotation_carries_a_to_b_by_their_angle():
    """exp(ψ) a = b, |ψ| = the angle between them, ψ ⟂ both; b = -a: a half turn ⟂ a."""
    rng = np.random.default_rng(6)
    a = rng.normal(size=(50, 3))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = so3.so3_exp(_rotvecs(rng, 50)) @ a[..., None]
    b = b[..., 0]
    b[:3] = a[:3]                           # equal
    b[3:6] = -a[3:6]                        # opposite
    psi = so3.shortest_rotation(a, b)
    np.testing.assert_allclose((so3.so3_exp(psi) @ a[..., None])[..., 0], b, atol=1e-12)
    angle = np.arccos(np.clip(np.sum(a * b, axis=1), -1.0, 1.0))
    np.testing.assert_allclose(np.linalg.norm(psi, axis=1), angle, atol=1e-7)
    np.testing.assert_allclose(np.sum(psi * a, axis=1), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.sum(psi * b, axis=1), 0.0, atol=1e-12)
    np.testing.assert_array_equal(psi[:3], 0.0)
    np.testing.assert_allclose(np.linalg.norm(psi[3:6], axis=1), np.pi)
    # near 0 the angle keeps its precision (atan2, not arccos)
    tiny = so3.shortest_rotation([1.0, 0.0, 0.0], [np.cos(1e-9), np.sin(1e-9), 0.0])
    np.testing.assert_allclose(tiny, [0.0, 0.0, 1e-9], rtol=1e-12)
