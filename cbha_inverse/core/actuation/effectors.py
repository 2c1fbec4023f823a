"""
Effectors: points on frames whose positions, and frames whose orientations, the inverse drives.

The paper (Sec. IV, ``J_e``) puts an identity block on the rows of the last frame; here an
effector is any point ``p = x_f + R_f o`` on a mobile frame ``f`` (the tip, a mid vertebra, a
gripper point), several at once, and may constrain the orientation of its frame as well
(``docs/effectors.md``):

- ``point``: 3 position rows. With retract increments ``dp = dx_f + dθ_f × r = dx_f - r × dθ_f``
  where ``r = R_f o``, the ``J_e`` block of the effector is ``[I, -r^]`` on frame ``f``;
- ``axis``: the position rows and 2 rotational rows: a unit axis ``u`` of the frame (in the
  frame's axes) points along a target direction ``d`` (world axes). The error is the rotation
  vector ``ψ`` of the shortest rotation taking ``d`` to ``a = R_f u``; its rows are its
  components on two unit vectors ``c = R_f v`` orthogonal to ``a`` (``v ⟂ u`` fixed in the
  frame): a rotation about the axis itself is free;
- ``pose``: the position rows and 3 rotational rows: the frame's orientation ``R_f`` is driven to
  a target ``R_t``; the error is ``ψ = log(R_f R_tᵀ)`` (world axes), its rows its components on
  the frame's own axes ``c = R_f e_i``.

A rotational row ``c`` moves by ``c · dθ_f`` to first order: its ``J_e`` row is ``[0, cᵀ]`` on
frame ``f`` (the retraction's increments rotate frames in world axes, ``R <- exp(dθ^) R``).

Weights and units: the QP's tracking term is ``½ Σ_rows (ω_row δ_row)²``
(:mod:`cbha_inverse.core.inverse.qp`). A position row's ``δ`` is in metres and its weight
``ω = position_weight`` is unit-free; a rotational row's ``δ`` is in radians and its weight is
``ω = orientation_weight · orientation_length``, ``orientation_length`` [m] a length: one radian
of orientation error weighs as much as ``orientation_length`` metres of position error (with
``orientation_weight`` 1). Both weights are per row (a scalar for all of the effector's rows of
that kind, or one per row).

The points, levers, rotational directions and orientation errors are computed by the compiled
kernels of :mod:`cbha_inverse.core._kernels.projection`, the ones the control tick's projection
uses; that projection applies ``J_e`` itself.
"""

import math

from cbha_inverse.core._kernels.projection import effector_levers, effector_points
import numpy as np

KINDS = ('point', 'axis', 'pose')
"""The effector kinds, by their code (0, 1, 2) in the compiled tick."""

ORIENTATION_ROWS = {'point': 0, 'axis': 2, 'pose': 3}
"""Rotational rows of each kind."""

DEFAULT_ORIENTATION_LENGTH = 0.1
"""Default ``orientation_length`` [m]: one radian of orientation error weighs as 0.1 m (one
degree as 1.75 mm) of position error."""

QUATERNION_TOLERANCE = 1e-3
"""A target quaternion whose norm differs from 1 by at most this is normalised; beyond, refused."""


class TargetRefused(ValueError):
    """An orientation target of the right shape whose value is refused (not finite, zero, ...)."""


class PointEffectors:
    """
    Effector points on mobile frames, each with its frame's orientation rows (module docstring).

    Parameters
    ----------
    names : sequence of str
        Effector names (``k`` of them).
    frames : (k,) array_like of int
        Frame of each point (``1..n``; the base cannot be an effector).
    offsets : (k, 3) array_like  [m]
        Points in their frame's axes.
    n_frames : int
        Number of frames (base included).
    kinds : sequence of str, optional
        Kind of each effector, one of :data:`KINDS` (default: every one a ``point``).
    axes : (k, 3) array_like, optional
        The axis of each ``axis`` effector in its frame's axes (normalised; non-zero; read only
        for ``axis`` effectors; default ``+x``, the backbone).
    position_weights : float, (k,) or sequence of (3,), optional  [-]
        ``ω`` of the position rows (default 1), per effector, each a scalar or one per row.
    orientation_weights : float, (k,) or sequence, optional  [-]
        Factor of each rotational row's weight (default 1), per effector, each a scalar or one
        per rotational row (2 for ``axis``, 3 for ``pose``).
    orientation_lengths : float or (k,) array_like, optional  [m]
        ``orientation_length`` of each effector (default :data:`DEFAULT_ORIENTATION_LENGTH`).

    Attributes
    ----------
    kinds : tuple of str
    kind_codes : (k,) int ndarray
        Index of each kind in :data:`KINDS`.
    axes : (k, 3) ndarray
        Unit axes in the frames' axes (``+x`` for other kinds).
    orientation_effectors : (o,) int ndarray
        The effector of each rotational row, effector order (``o`` rows in all).
    orientation_axes : (o, 3) ndarray
        Each rotational row's unit vector ``v`` in its frame's axes (its world direction is
        ``R_f v``).
    row_weights : (3k + o,) ndarray  [-, m/rad]
        ``ω`` of every row: the ``3k`` position rows (effector order), then the rotational rows.

    """

    def __init__(self, names, frames, offsets, n_frames, kinds=None, axes=None,
                 position_weights=None, orientation_weights=None, orientation_lengths=None):
        """Validate and store the effectors."""
        self.names = tuple(names)
        self.frames = np.ascontiguousarray(np.asarray(frames, dtype=np.int64).reshape(-1))
        self.offsets = np.ascontiguousarray(np.asarray(offsets, dtype=float).reshape(-1, 3))
        if not (len(self.names) == self.frames.size == self.offsets.shape[0]):
            raise ValueError('effectors: names, frames and offsets must have the same length')
        if self.frames.size == 0:
            raise ValueError('effectors: at least one effector is needed')
        if self.frames.min() < 1 or self.frames.max() >= n_frames:
            raise ValueError(f'effector frames must lie in 1..{n_frames - 1} (the base is fixed)')
        if not np.all(np.isfinite(self.offsets)):
            raise ValueError('effector offsets must be finite')
        self.n_frames = int(n_frames)
        k = self.frames.size
        self.kinds = ('point',) * k if kinds is None else tuple(kinds)
        if len(self.kinds) != k or any(kind not in KINDS for kind in self.kinds):
            raise ValueError(f'effectors: one kind per effector, each one of {", ".join(KINDS)}')
        self.kind_codes = np.array([KINDS.index(kind) for kind in self.kinds], dtype=np.int64)
        self.axes = np.tile([1.0, 0.0, 0.0], (k, 1))
        if axes is not None:
            given = np.asarray(axes, dtype=float).reshape(k, 3)
            for e, kind in enumerate(self.kinds):
                if kind == 'axis':
                    self.axes[e] = unit_vectors(given[e], f'axis of effector {self.names[e]!r}')
        self.orientation_lengths = _per_effector(
            DEFAULT_ORIENTATION_LENGTH if orientation_lengths is None else orientation_lengths,
            k, 'orientation_lengths')
        rows, effectors, weights = [], [], []
        for e, kind in enumerate(self.kinds):
            vectors = _row_axes(kind, self.axes[e])
            rows.extend(vectors)
            effectors.extend([e] * len(vectors))
            weights.extend(self.orientation_lengths[e] * _row_weights(
                orientation_weights, e, len(vectors), 'orientation_weights'))
        self.orientation_effectors = np.array(effectors, dtype=np.int64)
        self.orientation_axes = np.ascontiguousarray(np.array(rows, dtype=float).reshape(-1, 3))
        positions = np.concatenate([_row_weights(position_weights, e, 3, 'position_weights')
                                    for e in range(k)])
        self.row_weights = np.concatenate([positions, np.array(weights, dtype=float)])
        if not self.row_weights.any():
            raise ValueError('effectors: every row weight is zero (nothing to track)')

    @property
    def n_effectors(self):
        """Return the number of effectors ``k``."""
        return self.frames.size

    @property
    def n_rows(self):
        """Return the number of rows of ``J_e``: ``3k`` position rows plus the rotational rows."""
        return self.row_weights.size

    @property
    def axis_effectors(self):
        """Return the indices of the ``axis`` effectors (the order of direction targets)."""
        return tuple(e for e, kind in enumerate(self.kinds) if kind == 'axis')

    @property
    def pose_effectors(self):
        """Return the indices of the ``pose`` effectors (the order of quaternion targets)."""
        return tuple(e for e, kind in enumerate(self.kinds) if kind == 'pose')

    def levers(self, rotations):
        """
        Return ``r = R_f o`` for every effector.

        Parameters
        ----------
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations (frame axes → world).

        Returns
        -------
        (k, 3) ndarray  [m]

        """
        return effector_levers(np.ascontiguousarray(rotations, dtype=float), self.frames,
                               self.offsets)

    def positions(self, positions, rotations):
        """
        Return the world positions of the effector points.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations (frame axes → world).

        Returns
        -------
        (k, 3) ndarray  [m]

        """
        return effector_points(np.ascontiguousarray(positions, dtype=float),
                               np.ascontiguousarray(rotations, dtype=float), self.frames,
                               self.offsets)

    def rotations(self, rotations):
        """
        Return the rotation of every effector's frame.

        Parameters
        ----------
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations (frame axes → world).

        Returns
        -------
        (k, 3, 3) ndarray

        """
        return np.asarray(rotations, dtype=float)[self.frames].copy()

    def directions(self, rotations):
        """
        Return the world direction ``R_f u`` of every effector's axis (``+x`` for non-axis kinds).

        Parameters
        ----------
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations (frame axes → world).

        Returns
        -------
        (k, 3) ndarray
            Unit vectors.

        """
        return np.einsum('kij,kj->ki', np.asarray(rotations, dtype=float)[self.frames],
                         self.axes)

    def orientation_targets(self, directions=None, quaternions=None):
        """
        Validate orientation targets at the door and return them as the compiled tick reads them.

        Parameters
        ----------
        directions : (a, 3) array_like, optional
            Target direction of each ``axis`` effector (:attr:`axis_effectors` order), world
            axes; normalised, a zero or non-finite vector refused. ``(3,)`` for one.
        quaternions : (p, 4) array_like, optional
            Target orientation of each ``pose`` effector's frame (:attr:`pose_effectors` order),
            world axes, ``(x, y, z, w)`` as ROS; normalised when its norm is within
            :data:`QUATERNION_TOLERANCE` of 1, else refused (and any non-finite one).
            ``(4,)`` for one.

        Returns
        -------
        directions : (a, 3) ndarray or None
            Unit vectors (None when not given).
        rotations : (p, 3, 3) ndarray or None
            The quaternions' rotation matrices (None when not given).

        Raises
        ------
        ValueError
            On a wrong shape, or a refused value (:class:`TargetRefused`, a ``ValueError``); the
            message names the effector.

        """
        checked_directions = checked_rotations = None
        if directions is not None:
            names = [self.names[e] for e in self.axis_effectors]
            values = _target_array(directions, len(names), 3, 'directions', 'axis')
            checked_directions = np.array([unit_vectors(value, f'direction of {name!r}')
                                           for value, name in zip(values, names)]).reshape(-1, 3)
        if quaternions is not None:
            names = [self.names[e] for e in self.pose_effectors]
            values = _target_array(quaternions, len(names), 4, 'quaternions', 'pose')
            checked_rotations = np.array([rotation_of_quaternion(value, f'quaternion of {name!r}')
                                          for value, name in zip(values, names)]).reshape(-1, 3,
                                                                                          3)
        return checked_directions, checked_rotations


def unit_vectors(vector, what):
    """
    Return a finite non-zero 3-vector normalised.

    Parameters
    ----------
    vector : (3,) array_like
        The vector.
    what : str
        What it is, for the message.

    Returns
    -------
    (3,) ndarray

    Raises
    ------
    TargetRefused
        If it is not finite or is zero (a ``ValueError``).

    """
    value = np.asarray(vector, dtype=float).reshape(3)
    if not np.all(np.isfinite(value)):
        raise TargetRefused(f'{what} must be finite, got {value.tolist()}')
    largest = np.abs(value).max()
    if largest == 0.0:
        raise TargetRefused(f'{what} must not be zero')
    # divided by its largest component first: no overflow nor underflow in the norm
    value = value / largest
    return value / np.linalg.norm(value)


def rotation_of_quaternion(quaternion, what):
    """
    Return the rotation matrix of a unit quaternion ``(x, y, z, w)`` checked at the door.

    Parameters
    ----------
    quaternion : (4,) array_like
        ``(x, y, z, w)``.
    what : str
        What it is, for the message.

    Returns
    -------
    (3, 3) ndarray

    Raises
    ------
    TargetRefused
        If it is not finite or its norm differs from 1 by more than :data:`QUATERNION_TOLERANCE`
        (a ``ValueError``).

    """
    from cbha_inverse.core.so3 import matrix_from_quat
    value = np.asarray(quaternion, dtype=float).reshape(4)
    if not np.all(np.isfinite(value)):
        raise TargetRefused(f'{what} must be finite, got {value.tolist()}')
    norm = float(np.linalg.norm(value))
    if not abs(norm - 1.0) <= QUATERNION_TOLERANCE:
        raise TargetRefused(f'{what} must be a unit quaternion (x, y, z, w), its norm is '
                            f'{norm:.6g}')
    return matrix_from_quat(value)


def _target_array(values, count, width, name, kind):
    """Return orientation targets as a (count, width) array, or raise on a wrong shape."""
    array = np.asarray(values, dtype=float)
    if count == 0:
        raise ValueError(f'{name} given, but no effector is of kind {kind}')
    if array.shape == (width,) and count == 1:
        array = array.reshape(1, width)
    if array.shape != (count, width):
        raise ValueError(f'{name} must have shape ({count}, {width}) (one per {kind} effector), '
                         f'got {array.shape}')
    return array


def _per_effector(value, k, name):
    """Return a positive finite scalar or (k,) sequence as k floats."""
    values = np.array(np.broadcast_to(np.asarray(value, dtype=float), (k,)))
    if not np.all(np.isfinite(values)) or np.any(values <= 0.0):
        raise ValueError(f'{name} must be positive and finite, got {values.tolist()}')
    return values


def _row_weights(weights, e, rows, name):
    """Return the ``rows`` weights of effector ``e`` (a scalar or one per row), each >= 0."""
    if weights is None:
        values = np.ones(rows)
    else:
        given = weights if isinstance(weights, (int, float, np.number)) else weights[e]
        values = np.asarray(given, dtype=float).reshape(-1)
        if values.size == 1:
            values = np.full(rows, values[0])
        if values.size != rows:
            raise ValueError(f'{name}: effector {e} needs a scalar or {rows} weights, got '
                             f'{values.size}')
    if not np.all(np.isfinite(values)) or np.any(values < 0.0):
        raise ValueError(f'{name} must be finite and >= 0, got {values.tolist()}')
    return values


def _row_axes(kind, axis):
    """
    Return the rotational rows' unit vectors ``v`` (frame axes) of one effector.

    ``pose``: the frame's axes; ``axis``: two unit vectors orthogonal to ``axis`` (the first
    along the frame axis least aligned with it, made orthogonal; the second ``axis × v1``).
    """
    if kind == 'pose':
        return list(np.eye(3))
    if kind == 'point':
        return []
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    first = helper - axis * float(axis @ helper)
    first /= math.sqrt(float(first @ first))
    return [first, np.cross(axis, first)]
