"""
The latest transforms between named frames: what a node needs of TF to take a point in any frame.

A :class:`FrameTree` keeps, for every child frame, the last transform from its parent (as the
``/tf`` and ``/tf_static`` messages give them: translation and unit quaternion of the child in
the parent's axes) and carries a point from one frame to another through their common root.
Time is not interpolated: a target is a set-point, and the frames a user adds (a table, a
camera mount) are static. Unknown frames and frames of two separate trees are refused with a
:class:`LookupError` that names them.
"""

import math

from cbha_inverse.core.so3 import matrix_from_quat
import numpy as np


class FrameTree:
    """The latest transform of every child frame from its parent (a TF tree without time)."""

    def __init__(self):
        """Start without frames."""
        self._parents = {}            # child -> (parent, rotation (3, 3), translation (3,))

    @property
    def frames(self):
        """Return every frame named so far (children and parents), sorted."""
        named = set(self._parents) | {parent for parent, _, _ in self._parents.values()}
        return sorted(named)

    def set_transform(self, parent, child, translation, quaternion):
        """
        Store the transform of ``child`` in ``parent`` (replacing the child's previous one).

        Parameters
        ----------
        parent, child : str
            Frame names (different, non-empty).
        translation : (3,) array_like  [m]
            The child's origin in the parent's axes.
        quaternion : (4,) array_like
            The child's orientation in the parent (x, y, z, w); normalised.

        Raises
        ------
        ValueError
            If a name is empty, the values are not finite, the quaternion is zero, or the
            transform would close a loop of frames.

        """
        if not parent or not child or parent == child:
            raise ValueError(f'a transform needs two different frame names, got {parent!r} and '
                             f'{child!r}')
        t = np.asarray(translation, dtype=float).reshape(3)
        q = np.asarray(quaternion, dtype=float).reshape(4)
        norm = float(np.linalg.norm(q))
        if not (np.all(np.isfinite(t)) and math.isfinite(norm) and norm > 1e-9):
            raise ValueError(f'transform {parent!r} -> {child!r}: translation {t.tolist()} and '
                             f'quaternion {q.tolist()} must be finite, the quaternion non-zero')
        frame = parent
        while frame in self._parents:
            frame = self._parents[frame][0]
            if frame == child:
                raise ValueError(f'transform {parent!r} -> {child!r} would close a loop of '
                                 'frames')
        self._parents[child] = (parent, matrix_from_quat(q / norm), t)

    def transform_point(self, point, source, target):
        """
        Return a point given in ``source`` in the axes and origin of ``target``.

        Parameters
        ----------
        point : (3,) array_like  [m]
            The point, in ``source``.
        source, target : str
            Frame names.

        Returns
        -------
        (3,) ndarray  [m]

        Raises
        ------
        LookupError
            As :meth:`transform`.

        """
        p = np.asarray(point, dtype=float).reshape(3)
        if source == target:
            return p.copy()
        rotation, translation = self.transform(source, target)
        return rotation @ p + translation

    def transform(self, source, target):
        """
        Return the transform of ``source`` coordinates into ``target``: ``p_t = R p_s + t``.

        Parameters
        ----------
        source, target : str
            Frame names.

        Returns
        -------
        rotation : (3, 3) ndarray
            ``source``'s axes in ``target``'s.
        translation : (3,) ndarray  [m]
            ``source``'s origin in ``target``.

        Raises
        ------
        LookupError
            If a frame is unknown or the two frames are in separate trees (the message names
            them).

        """
        if source == target:
            return np.eye(3), np.zeros(3)
        known = self.frames
        for frame in (source, target):
            if frame not in known:
                listed = ', '.join(known) if known else 'none yet'
                raise LookupError(f'frame {frame!r} is unknown to TF (frames: {listed})')
        root_s, rotation_s, translation_s = self._to_root(source)
        root_t, rotation_t, translation_t = self._to_root(target)
        if root_s != root_t:
            raise LookupError(f'no transform between {source!r} and {target!r}: their trees '
                              f'have the roots {root_s!r} and {root_t!r}')
        return rotation_t.T @ rotation_s, rotation_t.T @ (translation_s - translation_t)

    def _to_root(self, frame):
        """Return the root of ``frame``'s tree and the frame's rotation and origin in it."""
        rotation, translation = np.eye(3), np.zeros(3)
        while frame in self._parents:
            parent, r, t = self._parents[frame]
            rotation, translation = r @ rotation, r @ translation + t
            frame = parent
        return frame, rotation, translation
