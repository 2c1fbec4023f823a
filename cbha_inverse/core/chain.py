"""
Chain of 6-DoF frames joined by compliance links: immutable model and separate state.

Frames i = 0..n; frame 0 is the fixed base; link i (0-based, i = 0..n-1) joins frame i to frame
i+1 (paper Sec. III). The model never changes after it is built; what changes during a
solve lives in a :class:`ChainState` (pinocchio's Model/Data split).
"""

from dataclasses import dataclass

from cbha_inverse.core._kernels.retraction import retract_frames
from cbha_inverse.core.links import checked_compliance
from cbha_inverse.core.so3 import quat_from_matrix
import numpy as np


def _frozen(array):
    """Return a read-only float copy of ``array``."""
    out = np.array(array, dtype=float)
    out.setflags(write=False)
    return out


def checked_array(value, shape, name):
    """
    Return ``value`` as a finite float ndarray of ``shape``; raise ValueError (naming it) if not.

    Parameters
    ----------
    value : array_like
        The argument.
    shape : tuple of int
        Required shape.
    name : str
        Argument name for the message.

    Returns
    -------
    ndarray

    """
    out = np.asarray(value, dtype=float)
    if out.shape != tuple(shape):
        raise ValueError(f'{name} must have shape {tuple(shape)}, got {out.shape}')
    if not np.all(np.isfinite(out)):
        raise ValueError(f'{name} must be finite (got NaN or inf)')
    return out


@dataclass(frozen=True, eq=False)
class ChainModel:
    """
    Immutable chain of n compliance links (n + 1 frames, frame 0 = fixed base).

    Attributes
    ----------
    compliances : (n, 6, 6) ndarray  [m/N, 1/N, rad/(N*m)]
        Compliance of link i (frame i clamped, loads at frame i+1, frame-i axes; paper eq. 2-4).
    stiffnesses : (n, 6, 6) ndarray
        Their inverses (symmetrised).
    rest_offsets : (n, 3) ndarray  [m]
        Origin of frame i+1 in frame-i axes at rest.
    rest_rotations : (n, 3, 3) ndarray
        Rotation of frame i+1 relative to frame i at rest.
    masses : (n,) ndarray  [kg]
        Masses lumped at frames 1..n.
    base_position : (3,) ndarray  [m]
    base_rotation : (3, 3) ndarray

    """

    compliances: np.ndarray
    stiffnesses: np.ndarray
    rest_offsets: np.ndarray
    rest_rotations: np.ndarray
    masses: np.ndarray
    base_position: np.ndarray
    base_rotation: np.ndarray

    @property
    def n_links(self):
        """Return the number of links n."""
        return self.compliances.shape[0]

    @property
    def n_frames(self):
        """Return the number of frames n + 1 (including the fixed base)."""
        return self.compliances.shape[0] + 1

    @property
    def length(self):
        """Return the sum of the rest link lengths [m] (a characteristic length of the chain)."""
        return float(np.sum(np.linalg.norm(self.rest_offsets, axis=-1)))

    @classmethod
    def from_compliances(cls, compliances, rest_offsets, masses=None, rest_rotations=None,
                         base_position=None, base_rotation=None):
        """
        Build a chain from link compliances and rest offsets.

        Parameters
        ----------
        compliances : (n, 6, 6) array_like
            Symmetric positive definite; link i joins frame i to frame i+1.
        rest_offsets : (n, 3) array_like  [m]
            Frame i+1 origin in frame-i axes at rest.
        masses : (n,) array_like, optional  [kg]
            Lumped at frames 1..n; zeros by default.
        rest_rotations : (n, 3, 3) array_like, optional
            Rest rotation of frame i+1 in frame i; identity by default.
        base_position : (3,) array_like, optional  [m]
            Zero by default.
        base_rotation : (3, 3) array_like, optional
            Identity by default.

        Returns
        -------
        ChainModel

        Raises
        ------
        ValueError
            On inconsistent shapes, a non-finite value (NaN or inf in any argument), a
            compliance that fails :func:`cbha_inverse.core.links.checked_compliance`, or a
            rotation that is not orthonormal.

        """
        comp = np.array(compliances, dtype=float)
        if comp.ndim != 3 or comp.shape[1:] != (6, 6) or comp.shape[0] < 1:
            raise ValueError(f'compliances must have shape (n, 6, 6), got {comp.shape}')
        n = comp.shape[0]
        comp = np.array([checked_compliance(c, f'compliance of link {i}')[0]
                         for i, c in enumerate(comp)])
        stiff = np.linalg.inv(comp)
        stiff = 0.5 * (stiff + np.swapaxes(stiff, 1, 2))
        offsets = checked_array(rest_offsets, (n, 3), 'rest_offsets')
        if rest_rotations is None:
            rots = np.broadcast_to(np.eye(3), (n, 3, 3))
        else:
            rots = checked_array(rest_rotations, (n, 3, 3), 'rest_rotations')
            _check_rotations(rots, 'rest_rotations')
        mass = np.zeros(n) if masses is None else np.array(masses, dtype=float)
        if mass.shape != (n,) or not np.all(np.isfinite(mass)) or np.any(mass < 0.0):
            raise ValueError(f'masses must be {n} finite non-negative values')
        base_x = (np.zeros(3) if base_position is None
                  else checked_array(base_position, (3,), 'base_position'))
        base_r = (np.eye(3) if base_rotation is None
                  else checked_array(base_rotation, (3, 3), 'base_rotation'))
        _check_rotations(base_r[None], 'base_rotation')
        return cls(_frozen(comp), _frozen(stiff), _frozen(offsets), _frozen(rots),
                   _frozen(mass), _frozen(base_x), _frozen(base_r))

    def transformed(self, position, rotation):
        """
        Return this chain moved rigidly: its base pose premultiplied by ``(position, rotation)``.

        ``T_w_b' = T_w_o T_w_b`` with ``T_w_o = (rotation, position)``: the new base sits at
        ``rotation @ base_position + position`` with axes ``rotation @ base_rotation``. Links,
        masses and every frame relative to the base are unchanged, so frames, routing points and
        effector points (all fixed in frame axes) move with it; world-axis loads such as gravity
        do not turn with it.

        Parameters
        ----------
        position : (3,) array_like  [m]
            Translation of the rigid motion (world axes).
        rotation : (3, 3) array_like
            Its rotation (a proper rotation matrix).

        Returns
        -------
        ChainModel

        Raises
        ------
        ValueError
            On a non-finite position or a rotation that is not a proper rotation.

        """
        p = checked_array(position, (3,), 'position')
        r = checked_array(rotation, (3, 3), 'rotation')
        _check_rotations(r[None], 'rotation')
        return ChainModel(self.compliances, self.stiffnesses, self.rest_offsets,
                          self.rest_rotations, self.masses,
                          _frozen(r @ self.base_position + p), _frozen(r @ self.base_rotation))


def _check_rotations(rots, name):
    """Raise ValueError unless every (3, 3) matrix is a proper rotation."""
    err = np.abs(rots @ np.swapaxes(rots, -1, -2) - np.eye(3)).max()
    if err > 1e-9 or np.any(np.linalg.det(rots) < 0.0):
        raise ValueError(f'{name} must be proper rotation matrices')


@dataclass(frozen=True, eq=False)
class ChainState:
    """
    Poses of the n + 1 frames of a chain (world axes).

    Attributes
    ----------
    positions : (n + 1, 3) ndarray  [m]
    rotations : (n + 1, 3, 3) ndarray

    """

    positions: np.ndarray
    rotations: np.ndarray

    @property
    def quaternions(self):
        """(n + 1, 4) ndarray: frame orientations as (x, y, z, w) quaternions."""
        return quat_from_matrix(self.rotations)


def rest_state(model):
    """
    Rest shape of a chain, composed from the base along the rest transforms.

    ``x_{i+1} = x_i + R_i d0_i``, ``R_{i+1} = R_i Q0_i``.

    Parameters
    ----------
    model : ChainModel
        The chain.

    Returns
    -------
    ChainState

    """
    n = model.n_links
    pos = np.empty((n + 1, 3))
    rot = np.empty((n + 1, 3, 3))
    pos[0] = model.base_position
    rot[0] = model.base_rotation
    for i in range(n):
        pos[i + 1] = pos[i] + rot[i] @ model.rest_offsets[i]
        rot[i + 1] = rot[i] @ model.rest_rotations[i]
    return ChainState(pos, rot)


def external_wrenches(model, tip_wrench=None, frame_wrenches=None, gravity=None):
    """
    Dead external wrenches on frames 1..n (world axes, at the frame origins).

    The one place where gravity becomes frame wrenches (the controller, the statics, the
    scenes and the plant all call it).

    Parameters
    ----------
    model : ChainModel
        The chain (masses are lumped at frames 1..n).
    tip_wrench : (6,) array_like, optional  [N, N*m]
        Added at the last frame.
    frame_wrenches : (n, 6) array_like, optional  [N, N*m]
        Wrench on each of frames 1..n.
    gravity : (3,) array_like, optional  [m/s^2]
        Acceleration of gravity; force ``m_i g`` on frame i.

    Returns
    -------
    (n, 6) ndarray  [N, N*m]

    """
    n = model.n_links
    ext = np.zeros((n, 6))
    if frame_wrenches is not None:
        ext += checked_array(frame_wrenches, (n, 6), 'frame_wrenches')
    if tip_wrench is not None:
        ext[-1] += checked_array(tip_wrench, (6,), 'tip_wrench')
    if gravity is not None:
        ext[:, :3] += model.masses[:, None] * checked_array(gravity, (3,), 'gravity')
    return ext


def retract(state, increments):
    """
    Apply world-axis increments to frames 1..n (frame 0 never moves).

    ``x_i <- x_i + dx_i``, ``R_i <- exp(dtheta_i) R_i`` (left multiplication, world axes).

    Parameters
    ----------
    state : ChainState
        Current poses.
    increments : (n, 6) array_like  [m, rad]
        (dx, dy, dz, rx, ry, rz) per moving frame.

    Returns
    -------
    ChainState
        A new state; ``state`` is not modified.

    """
    inc = checked_array(increments, (state.positions.shape[0] - 1, 6), 'increments')
    positions = np.array(state.positions, dtype=float, order='C')
    rotations = np.array(state.rotations, dtype=float, order='C')
    return ChainState(*retract_frames(positions, rotations, inc, in_place=True))
