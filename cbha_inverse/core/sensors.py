"""
String potentiometers: passive cables whose routed length is read (``docs/proprioception.md``).

A string potentiometer is a force-free cable routed through points fixed to frames (base plate,
guide vertebrae, end plate); its length is the sum of the straight spans between them, the same
routing geometry as the actuation cables (:class:`cbha_inverse.core.actuation.cables.CableGroup`
indexes it, :func:`cbha_inverse.core._kernels.cables.routing_lengths_into` evaluates it). Its raw
reading is affine in the length, ``reading = offset + gain * length``, with a noise of standard
deviation ``noise_std`` on the length.
"""

from cbha_inverse.core.actuation.cables import Cable, CableGroup, RoutedLengths
import numpy as np


class StringPots:
    """
    The string potentiometers of a scene, evaluated together.

    Parameters
    ----------
    names : sequence of str
        Sensor names, in reading order (``c`` of them).
    frames : sequence of (P_i,) array_like of int
        Frame of every routing point of each sensor, from its base end.
    offsets : sequence of (P_i, 3) array_like  [m]
        Routing points in their frame's axes.
    n_frames : int
        Number of frames of the chain (base included).
    reading_offset : (c,) array_like  [reading]
        Reading at zero length.
    reading_gain : (c,) array_like  [reading / m]
        Reading per metre of length (non-zero, finite).
    noise_std : (c,) array_like  [m]
        Standard deviation of the length noise (positive).

    """

    def __init__(self, names, frames, offsets, n_frames, reading_offset, reading_gain,
                 noise_std):
        """Index the routing and check the calibration."""
        self.names = tuple(names)
        c = len(self.names)
        if c == 0:
            raise ValueError('string pots: at least one sensor is needed')
        cables = [Cable(name, f, o) for name, f, o in zip(self.names, frames, offsets)]
        self._routes = RoutedLengths(CableGroup(cables, n_frames))
        self.n_frames = int(n_frames)
        self.reading_offset = _per_sensor(reading_offset, c, 'offset')
        self.reading_gain = _per_sensor(reading_gain, c, 'gain')
        self.noise_std = _per_sensor(noise_std, c, 'noise_std')
        if np.any(self.reading_gain == 0.0):
            raise ValueError('string pots: a gain must be non-zero')
        if np.any(self.noise_std <= 0.0):
            raise ValueError('string pots: noise_std must be positive')

    @property
    def routing(self):
        """
        Return the routing arrays of the compiled length evaluation.

        Returns
        -------
        tuple of ndarray
            Frames (P,), offsets (P, 3), span start, end and owner (S,), point owner (P,): the
            arguments of :func:`cbha_inverse.core._kernels.cables.routing_lengths_into`.

        """
        return self._routes.routing

    @property
    def n_sensors(self):
        """Return the number of sensors ``c``."""
        return len(self.names)

    def lengths(self, positions, rotations):
        """
        Return the routed length of every sensor.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations.

        Returns
        -------
        (c,) ndarray  [m]

        """
        return self.lengths_and_jacobian(positions, rotations)[0]

    def lengths_and_jacobian(self, positions, rotations):
        """
        Return the lengths and their Jacobian ``J_s = d(length)/dq`` (c, 6n).

        As :meth:`cbha_inverse.core.actuation.cables.RoutedLengths.lengths_and_jacobian`, the
        Jacobian a buffer of this object (overwritten by the next call).
        """
        return self._routes.lengths_and_jacobian(positions, rotations)

    def readings(self, lengths):
        """
        Return the raw readings of lengths: ``offset + gain * length``.

        Parameters
        ----------
        lengths : (c,) array_like  [m]
            Routed lengths.

        Returns
        -------
        (c,) ndarray  [reading]

        """
        return self.reading_offset + self.reading_gain * np.asarray(lengths, dtype=float)

    def lengths_of(self, readings):
        """
        Return the lengths of raw readings (the inverse of :meth:`readings`).

        Parameters
        ----------
        readings : (c,) array_like  [reading]
            Raw readings.

        Returns
        -------
        (c,) ndarray  [m]

        """
        return (np.asarray(readings, dtype=float) - self.reading_offset) / self.reading_gain

    def recalibrated(self, reading_offset=None, reading_gain=None, noise_std=None):
        """
        Return the same sensors with another calibration (None keeps the current one).

        Parameters
        ----------
        reading_offset, reading_gain, noise_std : (c,) array_like, optional
            As the constructor.

        Returns
        -------
        StringPots

        """
        pick = (lambda new, old: old if new is None else new)
        other = object.__new__(StringPots)
        other.__dict__.update(self.__dict__)
        other.reading_offset = _per_sensor(pick(reading_offset, self.reading_offset),
                                           self.n_sensors, 'offset')
        other.reading_gain = _per_sensor(pick(reading_gain, self.reading_gain),
                                         self.n_sensors, 'gain')
        other.noise_std = _per_sensor(pick(noise_std, self.noise_std), self.n_sensors,
                                      'noise_std')
        if np.any(other.reading_gain == 0.0) or np.any(other.noise_std <= 0.0):
            raise ValueError('string pots: a gain must be non-zero, noise_std positive')
        other._routes = RoutedLengths(self._routes.group)   # buffers of its own
        return other


def _per_sensor(value, count, what):
    """Return ``value`` broadcast to ``count`` finite floats."""
    array = np.array(np.broadcast_to(np.asarray(value, dtype=float), (count,)))
    if not np.all(np.isfinite(array)):
        raise ValueError(f'string pots: {what} must be finite')
    return array
