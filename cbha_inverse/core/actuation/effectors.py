"""
Effectors: points on frames whose positions the inverse model drives (paper Sec. IV, ``J_e``).

The paper puts an identity block on the rows of the last frame; here an effector is any point
``p = x_f + R_f o`` on a mobile frame ``f`` (the tip, a mid vertebra, a gripper point), several
at once. With retract increments ``dp = dx_f + dθ_f × r = dx_f - r × dθ_f`` where ``r = R_f o``,
i.e. the ``J_e`` block of the effector is ``[I, -r^]`` on frame ``f``. The points and levers
are computed by the compiled kernels of :mod:`cbha_inverse.core._kernels.projection`
(``effector_points``, ``effector_levers``), the ones the control tick's projection uses; that
projection applies ``J_e`` itself (``project_effectors``).
"""

from cbha_inverse.core._kernels.projection import effector_levers, effector_points
import numpy as np


class PointEffectors:
    """
    Points on mobile frames.

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

    """

    def __init__(self, names, frames, offsets, n_frames):
        """Validate and store the effector points."""
        self.names = tuple(names)
        self.frames = np.ascontiguousarray(np.asarray(frames, dtype=np.int64).reshape(-1))
        self.offsets = np.ascontiguousarray(np.asarray(offsets, dtype=float).reshape(-1, 3))
        if not (len(self.names) == self.frames.size == self.offsets.shape[0]):
            raise ValueError('effectors: names, frames and offsets must have the same length')
        if self.frames.size == 0:
            raise ValueError('effectors: at least one effector is needed')
        if self.frames.min() < 1 or self.frames.max() >= n_frames:
            raise ValueError(f'effector frames must lie in 1..{n_frames - 1} (the base is fixed)')
        self.n_frames = int(n_frames)

    @property
    def n_effectors(self):
        """Return the number of effector points ``k``."""
        return self.frames.size

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
