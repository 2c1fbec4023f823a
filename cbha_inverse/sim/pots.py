"""
The simulated string potentiometers: raw readings of the plant's true shape (no ROS).

:class:`SimulatedPots` reads the routed lengths of the plant scene's pots
(:class:`cbha_inverse.core.sensors.StringPots`) at the plant's true frames, adds Gaussian
length noise from a random stream of its own and maps them to raw readings with the plant's
own offset and gain per pot (which the controller's scene need not know), in the order of the
scene's ``sensors`` block (the driver's ``BHAReadings.cablepull`` order for the CBHA). A fault
for tests: one pot can be made to stick (its reading frozen at its last value, as a jammed
cable or a broken wiper gives).
"""

import numpy as np


def per_pot(label, values, count):
    """
    Return one value per pot from ``values`` (one value: every pot).

    Parameters
    ----------
    label : str
        Parameter name, for the error.
    values : sequence of float
        ``count`` values, or one.
    count : int
        Pots.

    Returns
    -------
    (count,) ndarray

    Raises
    ------
    ValueError
        On another number of values or a non-finite one.

    """
    array = np.asarray([float(v) for v in values], dtype=float)
    if array.size == 1:
        array = np.full(count, array[0])
    if array.size != count or not np.all(np.isfinite(array)):
        raise ValueError(f'{label} needs 1 or {count} finite values, got {list(values)}')
    return array


class SimulatedPots:
    """
    Noisy raw readings of a plant's string potentiometers.

    Parameters
    ----------
    sensors : cbha_inverse.core.sensors.StringPots
        The plant scene's pots.
    offset : sequence of float or None  [reading]
        The plant's offset per pot (one value: all); None: the scene's.
    gain : sequence of float or None  [reading / m]
        The plant's gain per pot (one value: all, non-zero); None: the scene's.
    noise_std : float  [m]
        Standard deviation of the length noise.
    seed : int
        Seed; the readings draw from the stream ``SeedSequence(seed, spawn_key=(2,))``.
    stuck_pot : int or None
        Index of the pot (``sensors`` order) that sticks when :meth:`read` is told so; None:
        none.

    """

    def __init__(self, sensors, offset=None, gain=None, noise_std=1e-4, seed=0, stuck_pot=None):
        """Check the calibration and start the noise stream."""
        c = sensors.n_sensors
        if stuck_pot is not None and not 0 <= stuck_pot < c:
            raise ValueError(f'string_pot_stuck must be a pot index 0-{c - 1}, got {stuck_pot}')
        offset = None if offset is None else per_pot('string_pot_offset', offset, c)
        gain = None if gain is None else per_pot('string_pot_gain', gain, c)
        if gain is not None and np.any(gain == 0.0):
            raise ValueError('string_pot_gain must be non-zero')
        if not (np.isfinite(noise_std) and noise_std >= 0.0):
            raise ValueError(f'string_pot_noise_std must be >= 0, got {noise_std}')
        self.sensors = sensors.recalibrated(reading_offset=offset, reading_gain=gain)
        self.names = sensors.names
        self.noise_std = float(noise_std)
        self.stuck_pot = stuck_pot
        self._rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(2,)))
        self._last = None
        self._frozen = None

    def read(self, positions, rotations, stuck=False):
        """
        Return the raw readings of the pots at a plant state.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            The plant's frame origins.
        rotations : (n + 1, 3, 3) ndarray
            The plant's frame rotations.
        stuck : bool
            Whether ``stuck_pot`` is stuck: it then reads, from this call on, what it read in
            the previous call (this one's reading if there was none) until :meth:`unstick`.

        Returns
        -------
        (c,) ndarray  [reading]

        """
        lengths = self.sensors.lengths(positions, rotations)
        noise = self._rng.normal(0.0, self.noise_std, lengths.size)
        readings = self.sensors.readings(lengths + noise)
        if stuck and self.stuck_pot is not None:
            if self._frozen is None:
                self._frozen = (readings if self._last is None else self._last)[self.stuck_pot]
            readings[self.stuck_pot] = self._frozen
        self._last = readings
        return readings

    def unstick(self):
        """Free the stuck pot: the next reading is the true one again."""
        self._frozen = None
