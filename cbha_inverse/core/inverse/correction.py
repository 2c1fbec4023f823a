"""Closed-loop target correction from measured effector positions (`docs/design.md`)."""

import numpy as np


class TargetCorrector:
    """
    Closed-loop target correction: integral action on the measured effector error.

    The model is asked to reach ``target + c``; every update integrates
    ``c ← c + gain · (target - measured)`` and clamps ``|c|`` per effector to ``max_correction``.
    Anti-windup: while the solver reports saturation, an update that would increase ``|c|`` is
    skipped (conditional integration). Effectors without a measurement (NaN rows) are not
    integrated. Open loop is ``gain = 0`` (the paper's mode).

    Parameters
    ----------
    n_effectors : int
        ``k``.
    gain : float
        Integral gain per update (dimensionless, 0..1; e.g. 0.1 at 50 Hz).
    max_correction : float  [m]
        Largest correction per effector.

    """

    def __init__(self, n_effectors, gain=0.1, max_correction=0.03):
        """Start with no correction."""
        if not 0.0 <= gain <= 1.0:
            raise ValueError('gain must lie in [0, 1]')
        self.gain = float(gain)
        self.max_correction = float(max_correction)
        self.correction = np.zeros((int(n_effectors), 3))

    def reset(self):
        """Forget the integral."""
        self.correction[:] = 0.0

    def update(self, target, measured, saturated=False):
        """
        Integrate one measurement and return the corrected target.

        Parameters
        ----------
        target : (k, 3) array_like  [m]
            Desired effector positions.
        measured : (k, 3) array_like or None  [m]
            Measured positions (NaN rows: not measured; None: nothing measured).
        saturated : bool
            Whether the last tick saturated (anti-windup).

        Returns
        -------
        (k, 3) ndarray  [m]
            ``target + c``.

        """
        target = np.asarray(target, dtype=float).reshape(self.correction.shape)
        if measured is not None and self.gain > 0.0:
            error = target - np.asarray(measured, dtype=float).reshape(target.shape)
            valid = np.all(np.isfinite(error), axis=1)
            proposal = self.correction + self.gain * np.where(valid[:, None], error, 0.0)
            norms = np.linalg.norm(proposal, axis=1)
            too_long = norms > self.max_correction
            proposal[too_long] *= (self.max_correction / norms[too_long])[:, None]
            if saturated:
                grows = np.linalg.norm(proposal, axis=1) > np.linalg.norm(self.correction, axis=1)
                proposal[grows] = self.correction[grows]
            self.correction = proposal
        return self.corrected(target)

    def corrected(self, target):
        """
        Return the corrected target ``target + c`` without integrating anything.

        One numpy operation: the set-point of every tick between two measurements.

        Parameters
        ----------
        target : (k, 3) ndarray, or (3,) for one effector  [m]
            Desired effector positions (float).

        Returns
        -------
        (k, 3) ndarray  [m]

        Raises
        ------
        ValueError
            If ``target`` has another shape (a (3,) target is not spread over k > 1 effectors).

        """
        correction = self.correction
        shape = target.shape
        if shape != correction.shape and not (shape == (3,) and correction.shape[0] == 1):
            raise ValueError(f'target must have shape {correction.shape}, got {shape}')
        return correction + target
