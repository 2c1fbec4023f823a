"""Closed-loop target correction from measured effector positions (`docs/design.md`)."""

import numpy as np

#: [m] a predicted gap longer than this names the direction the reach blocks (shorter: its
#: direction is noise, and the conditional integration applies)
MIN_BLOCKED_GAP = 1e-4


class TargetCorrector:
    """
    Closed-loop target correction: integral action on the measured effector error.

    The model is asked to reach ``target + c``; every update integrates
    ``c ← c + gain · (target - measured)`` and clamps ``|c|`` per effector to ``max_correction``.
    Anti-windup, while the solver holds (a bound, the reach or its convergence): where the
    model predicts a gap ``p`` between the corrected target it was given and the effector
    position it reached, the reach blocks the direction of ``p`` only, so the update loses its
    component outward along ``p`` and integrates the rest: the tip slides along the edge of the
    reach to the point nearest the target instead of staying where the hold began. Where no gap
    is predicted (``|p|`` below :data:`MIN_BLOCKED_GAP`, or no ``p`` given), an update that would
    increase ``|c|`` is skipped (conditional integration). Effectors without a measurement (NaN
    rows) are not integrated. Open loop is ``gain = 0`` (the paper's mode).

    An effector pressing a surface (a contact target, ``docs/touch.md``) sits inside its
    target's normal by design: :meth:`set_touch_normal` makes the corrector integrate only the
    error's part in the surface's tangent plane for it.

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
        # the unit normal of each touching effector's surface (zero rows: no touch)
        self.touch_normals = np.zeros((int(n_effectors), 3))

    def set_touch_normal(self, effector, normal):
        """
        Integrate only an effector's error in a surface's tangent plane (None: all of it).

        The correction's part along the normal is dropped as well: the contact target sets the
        depth (``docs/touch.md``).

        Parameters
        ----------
        effector : int
            The effector's index.
        normal : (3,) array_like or None
            The surface's unit normal (finite, nonzero; normalised), or None to clear.

        Raises
        ------
        ValueError
            On an effector out of range or a zero or non-finite normal.

        """
        if not (isinstance(effector, (int, np.integer))
                and 0 <= effector < self.correction.shape[0]):
            raise ValueError(f'effector must lie in 0..{self.correction.shape[0] - 1}, '
                             f'got {effector!r}')
        if normal is None:
            self.touch_normals[effector] = 0.0
            return
        normal = np.asarray(normal, dtype=float).reshape(3)
        length = float(np.linalg.norm(normal))
        if not (np.all(np.isfinite(normal)) and length > 0.0):
            raise ValueError(f'touch normal must be finite and nonzero, got {normal.tolist()}')
        normal = normal / length
        self.touch_normals[effector] = normal
        self.correction[effector] -= normal * (normal @ self.correction[effector])

    def reset(self):
        """Forget the integral."""
        self.correction[:] = 0.0

    def update(self, target, measured, saturated=False, predicted_gap=None):
        """
        Integrate one measurement and return the corrected target.

        Parameters
        ----------
        target : (k, 3) array_like  [m]
            Desired effector positions.
        measured : (k, 3) array_like or None  [m]
            Measured positions (NaN rows: not measured; None: nothing measured).
        saturated : bool
            Whether the last tick held: status in
            :data:`~cbha_inverse.core.inverse.results.HELD_STATUSES` (anti-windup).
        predicted_gap : (k, 3) array_like or None  [m]
            The last tick's corrected target minus the effector positions its model reached
            (``goal - result.effector_positions``): the direction the reach blocks while it
            holds. None: conditional integration for every effector.

        Returns
        -------
        (k, 3) ndarray  [m]
            ``target + c``.

        """
        target = np.asarray(target, dtype=float).reshape(self.correction.shape)
        if measured is not None and self.gain > 0.0:
            error = target - np.asarray(measured, dtype=float).reshape(target.shape)
            valid = np.all(np.isfinite(error), axis=1)
            increment = self.gain * np.where(valid[:, None], error, 0.0)
            # a touching effector: the tangential part only
            normals = self.touch_normals
            increment -= normals * np.einsum('ki,ki->k', increment, normals)[:, None]
            blocked = np.zeros(increment.shape[0], dtype=bool)
            if saturated and predicted_gap is not None:
                blocked, increment = _without_blocked_part(increment, predicted_gap)
            proposal = self.correction + increment
            norms = np.linalg.norm(proposal, axis=1)
            too_long = norms > self.max_correction
            proposal[too_long] *= (self.max_correction / norms[too_long])[:, None]
            if saturated:
                grows = np.linalg.norm(proposal, axis=1) > np.linalg.norm(self.correction, axis=1)
                held = grows & ~blocked
                proposal[held] = self.correction[held]
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


def _without_blocked_part(increment, predicted_gap):
    """
    Drop the part of each correction increment that points outward along its predicted gap.

    Parameters
    ----------
    increment : (k, 3) ndarray  [m]
        ``gain · (target - measured)`` per effector.
    predicted_gap : (k, 3) array_like  [m]
        Corrected target minus the model's effector position, per effector.

    Returns
    -------
    blocked : (k,) ndarray of bool
        The effectors whose gap is longer than :data:`MIN_BLOCKED_GAP` (their increment is
        projected).
    increment : (k, 3) ndarray  [m]
        The increment without its outward component ``max(Δ·u, 0) u`` along the gap's unit
        direction ``u``, for the blocked effectors; unchanged for the others.

    """
    gap = np.asarray(predicted_gap, dtype=float).reshape(increment.shape)
    lengths = np.linalg.norm(gap, axis=1)
    blocked = lengths > MIN_BLOCKED_GAP          # False for NaN rows as well
    direction = np.zeros_like(gap)
    direction[blocked] = gap[blocked] / lengths[blocked, None]
    outward = np.maximum(np.sum(increment * direction, axis=1), 0.0)
    return blocked, increment - outward[:, None] * direction
