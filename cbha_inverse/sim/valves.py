"""
The valve line of the simulated CBHA: a transport latency, then first-order valves.

A set-point sent at time ``t_c`` reaches the valves at ``t_c + latency`` and holds until the next
one arrives. Each valve pressure ``p`` follows its set-point ``s`` as ``tau dp/dt = s - p``
(Bosman et al. 2015, section V: ``tau`` = 10 ms, latency 3 ms), whose exact solution over a
constant set-point is :func:`first_order_step`. :class:`ValveLine` steps that solution from
arrival to arrival, so its pressures are exact for piecewise-constant set-points whatever the
times it is evaluated at (the plant's ticks). ``cbha_sim`` runs it online;
:func:`cbha_inverse.identify.samples.valve_pressures` evaluates the same model over a recorded
command history. No ROS.
"""

import collections
import math

import numpy as np


def first_order_step(pressure, setpoint, elapsed, time_constant):
    """
    Return the pressure of a first-order valve after ``elapsed`` seconds at a constant set-point.

    ``p(t0 + e) = s + (p(t0) - s) exp(-e / tau)``; ``tau = 0``: the valve follows at once.

    Parameters
    ----------
    pressure : (..., m) array_like  [Pa]
        Pressures at the start of the interval.
    setpoint : (..., m) array_like  [Pa]
        The set-points held over the interval.
    elapsed : float or (..., 1) array_like  [s]
        Interval lengths (>= 0), broadcast against the pressures.
    time_constant : float  [s]
        The valves' time constant ``tau`` (>= 0).

    Returns
    -------
    (..., m) ndarray  [Pa]
        The pressures at the end of the interval (a new array).

    """
    pressure = np.asarray(pressure, dtype=float)
    setpoint = np.asarray(setpoint, dtype=float)
    elapsed = np.asarray(elapsed, dtype=float)
    if time_constant == 0.0:
        shape = np.broadcast(pressure, setpoint, elapsed).shape
        return np.broadcast_to(setpoint, shape).copy()
    return setpoint + (pressure - setpoint) * np.exp(-elapsed / time_constant)


class ValveLine:
    """
    Delayed set-points driving first-order valves, stepped exactly between arrivals.

    Parameters
    ----------
    size : int
        Number of valves ``m``.
    latency : float  [s]
        Transport delay from :meth:`send` to the valves (>= 0).
    time_constant : float  [s]
        First-order valve response ``tau`` (>= 0).

    Raises
    ------
    ValueError
        On a negative or non-finite latency or time constant.

    Notes
    -----
    Times are those of one clock (the node clock in ``cbha_sim``). A clock that jumps back (a
    looped bag) is a pause: the pressures do not move over the jump.

    """

    def __init__(self, size, latency, time_constant):
        if not all(math.isfinite(v) and v >= 0.0 for v in (latency, time_constant)):
            raise ValueError(f'latency and time_constant must be finite and >= 0, got '
                             f'{latency!r} and {time_constant!r}')
        self.size = int(size)
        self.latency = float(latency)
        self.time_constant = float(time_constant)
        self.reset()

    def reset(self):
        """Vent every valve, drop the set-points in transit."""
        self._pressures = np.zeros(self.size)
        self._setpoint = np.zeros(self.size)
        self._pending = collections.deque()
        self._time = None

    @property
    def pressures(self):
        """(m,) ndarray [Pa]: the valve pressures at the last :meth:`advance` (a copy)."""
        return self._pressures.copy()

    @property
    def setpoint(self):
        """(m,) ndarray [Pa]: the set-point acting on the valves (a copy)."""
        return self._setpoint.copy()

    def send(self, time, setpoint):
        """
        Send a set-point; it reaches the valves ``latency`` seconds later.

        Parameters
        ----------
        time : float  [s]
            When it is sent.
        setpoint : (m,) array_like  [Pa]
            The valve set-points (validated by the caller).

        """
        setpoint = np.array(setpoint, dtype=float)
        if setpoint.shape != (self.size,):
            raise ValueError(f'setpoint must have shape ({self.size},), got {setpoint.shape}')
        self._pending.append((float(time) + self.latency, setpoint))

    def advance(self, time):
        """
        Move the valves to ``time`` through every set-point that arrived meanwhile.

        Parameters
        ----------
        time : float  [s]
            The new time.

        Returns
        -------
        (m,) ndarray  [Pa]
            The valve pressures at ``time``.

        """
        time = float(time)
        if self._time is None:
            # at rest with a zero set-point until the first arrival: nothing moves before it
            self._time = min(time, self._pending[0][0]) if self._pending else time
        elif time < self._time:
            self._time = time
        tau = self.time_constant
        while self._pending and self._pending[0][0] <= time:
            arrival, setpoint = self._pending.popleft()
            self._pressures = first_order_step(self._pressures, self._setpoint,
                                               max(arrival - self._time, 0.0), tau)
            self._time = max(self._time, arrival)
            self._setpoint = setpoint
        self._pressures = first_order_step(self._pressures, self._setpoint, time - self._time,
                                           tau)
        self._time = time
        return self.pressures
