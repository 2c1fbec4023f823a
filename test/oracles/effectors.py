"""
The effector Jacobian ``J_e`` in numpy (oracle of the compiled effector projection).

An effector is a point ``p = x_f + R_f o`` on a mobile frame ``f``; with retract increments
``dp = dx_f + dθ_f × r`` where ``r = R_f o``, i.e. the ``J_e`` block of the effector is
``[I, -r^]`` on frame ``f`` (paper Sec. IV). The compiled kernels of
:mod:`cbha_inverse.core._kernels.projection` apply it inside the tick's projection; these are
the dense and the applied forms, written independently for the tests.
"""

import numpy as np


def effector_levers(effectors, rotations):
    """
    Return the levers ``r = R_f o`` of the effector points.

    Parameters
    ----------
    effectors : cbha_inverse.core.actuation.effectors.PointEffectors
        The effector points.
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations (frame axes → world).

    Returns
    -------
    (k, 3) ndarray  [m]

    """
    return np.einsum('kij,kj->ki', np.asarray(rotations)[effectors.frames], effectors.offsets)


def apply_effector_jacobian(effectors, rotations, increments):
    """
    Return ``J_e dq`` for one or many increment fields.

    Parameters
    ----------
    effectors : cbha_inverse.core.actuation.effectors.PointEffectors
        The effector points.
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations at the linearisation state.
    increments : (n, 6) or (n, 6, c) ndarray  [m, rad]
        Increments of frames ``1..n`` (``dx``, world-axis ``dθ``), optionally ``c`` columns.

    Returns
    -------
    (k, 3) or (k, 3, c) ndarray  [m]
        Effector displacements.

    """
    inc = np.asarray(increments)[effectors.frames - 1]
    levers = effector_levers(effectors, rotations)
    if inc.ndim == 2:
        return inc[:, :3] + np.cross(inc[:, 3:], levers)
    return inc[:, :3, :] + np.cross(inc[:, 3:, :], levers[:, :, None], axis=1)


def effector_jacobian(effectors, rotations):
    """
    Return the dense ``J_e``.

    Parameters
    ----------
    effectors : cbha_inverse.core.actuation.effectors.PointEffectors
        The effector points.
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations (frame axes → world).

    Returns
    -------
    (3k, 6n) ndarray
        Rows of the effector coordinates, columns of the increments of frames ``1..n``.

    """
    n = effectors.n_frames - 1
    jac = np.zeros((3 * effectors.n_effectors, 6 * n))
    for e, (frame, r) in enumerate(zip(effectors.frames, effector_levers(effectors, rotations))):
        dof = 6 * (frame - 1)
        jac[3 * e:3 * e + 3, dof:dof + 3] = np.eye(3)
        jac[3 * e:3 * e + 3, dof + 3:dof + 6] = -np.array(
            [[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
    return jac
