r"""
An excitation program: pressure holds joined by linear ramps, as a function of time (no ROS).

A program is a list of *holds* (one actuation vector each, held for ``hold_time``), entered
from a ``start`` actuation and left to an ``end`` actuation; consecutive set-points are joined
by linear ramps of ``ramp_time``, so a real arm never sees a step::

    actuation
      ^        hold 0            hold 1                   hold n-1
      |      ________          ________                 ________
      |     /        \        /        \     ...       /        \
      |____/          \______/          \____  ...  __/          \____ end
      +----+--------+---------+--------+----------------------------+----> t
      0    r      r + h    2r + h   2r + 2h                 (n + 1) r + n h = duration

Every hold, the start and the end must lie within the actuator bounds. Units are those of the
actuators: gauge Pa for cavities (N for cables).
"""

import math

import numpy as np

DEFAULT_HOLD_TIME = 3.0
"""Default hold duration [s] (a few seconds: the arm settles, the samples are quasi-static)."""

DEFAULT_RAMP_TIME = 1.0
"""Default ramp duration [s] between two set-points."""


def _time(value, name):
    """Return a finite positive duration [s] or raise ``ValueError`` naming it."""
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ValueError(f'{name} must be a number of seconds, got {value!r}') from None
    if not math.isfinite(value) or value <= 0.0:
        raise ValueError(f'{name} must be a finite number of seconds > 0, got {value}')
    return value


def check_bounds(lower, upper):
    """
    Return validated actuator bounds.

    Parameters
    ----------
    lower, upper : (m,) array_like  [Pa or N]
        Finite, ``lower <= upper``, m >= 1.

    Returns
    -------
    lower, upper : (m,) ndarray  [Pa or N]

    Raises
    ------
    ValueError
        On other shapes, non-finite values or a lower bound above its upper bound.

    """
    lower = np.asarray(lower, dtype=float)
    upper = np.asarray(upper, dtype=float)
    if lower.ndim != 1 or lower.shape != upper.shape or lower.size == 0:
        raise ValueError(f'lower and upper must be two (m,) arrays, got shapes {lower.shape} and '
                         f'{upper.shape}')
    if not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper))):
        raise ValueError('actuator bounds must be finite')
    if np.any(lower > upper):
        raise ValueError(f'lower bounds {lower.tolist()} exceed upper bounds {upper.tolist()}')
    return lower, upper


def _within(values, lower, upper, what):
    """Check a (m,) actuation against the bounds; return it as a float array."""
    values = np.asarray(values, dtype=float)
    if values.shape != lower.shape:
        raise ValueError(f'{what} must have {lower.size} values, got shape {values.shape}')
    if not np.all(np.isfinite(values)):
        raise ValueError(f'{what} must be finite, got {values.tolist()}')
    outside = np.flatnonzero((values < lower) | (values > upper))
    if outside.size:
        k = int(outside[0])
        raise ValueError(f'{what}: value {values[k]:g} of actuator {k} is outside its bounds '
                         f'[{lower[k]:g}, {upper[k]:g}]')
    return values


def mid_range(lower, upper):
    """
    Return the middle of each actuator's range.

    Parameters
    ----------
    lower, upper : (m,) array_like  [Pa]
        Actuator bounds.

    Returns
    -------
    (m,) ndarray  [Pa]
        ``(lower + upper) / 2``.

    """
    lower, upper = check_bounds(lower, upper)
    return 0.5 * (lower + upper)


class ExcitationProgram:
    """
    Holds joined by linear ramps: the actuation as a function of time (immutable).

    Parameters
    ----------
    holds : (n, m) array_like  [Pa]
        The actuation of each hold, scene actuator order; n >= 1.
    lower, upper : (m,) array_like  [Pa]
        Actuator bounds; every hold, ``start`` and ``end`` must lie within them.
    hold_time : float  [s]
        Duration of each hold (> 0).
    ramp_time : float  [s]
        Duration of each linear ramp (> 0): start to hold 0, hold i to hold i + 1, last hold
        to end.
    start, end : (m,) array_like, optional  [Pa]
        Actuation at t = 0 and after the program (default: mid range).
    labels : sequence of str, optional
        One description per hold (default ``'hold i'``).

    Raises
    ------
    ValueError
        On wrong shapes, non-finite values, values outside the bounds or times that are not
        finite and positive.

    Attributes
    ----------
    hold_pressures : (n, m) ndarray  [Pa]
        The holds (read-only).
    lower, upper, start, end : (m,) ndarray  [Pa]
        Read-only.
    hold_time, ramp_time : float  [s]
    labels : tuple of str
    knot_times : (2 n + 2,) ndarray  [s]
        Times of the corners of the piecewise-linear actuation: 0, then the start and end of
        each hold, then ``duration``.

    """

    def __init__(self, holds, lower, upper, *, hold_time=DEFAULT_HOLD_TIME,
                 ramp_time=DEFAULT_RAMP_TIME, start=None, end=None, labels=None):
        """Validate and freeze the program."""
        lower, upper = check_bounds(lower, upper)
        holds = np.array(holds, dtype=float)
        if holds.ndim != 2 or holds.shape[0] < 1 or holds.shape[1] != lower.size:
            raise ValueError(f'holds must be an (n >= 1, {lower.size}) array, got shape '
                             f'{holds.shape}')
        for i, row in enumerate(holds):
            _within(row, lower, upper, f'hold {i}')
        mid = 0.5 * (lower + upper)
        start = _within(mid if start is None else start, lower, upper, 'start')
        end = _within(mid if end is None else end, lower, upper, 'end')
        self.hold_time = _time(hold_time, 'hold_time')
        self.ramp_time = _time(ramp_time, 'ramp_time')
        n = holds.shape[0]
        labels = tuple(f'hold {i}' for i in range(n)) if labels is None else tuple(
            str(v) for v in labels)
        if len(labels) != n:
            raise ValueError(f'labels must have {n} entries (one per hold), got {len(labels)}')
        self.labels = labels
        period = self.ramp_time + self.hold_time
        hold_starts = self.ramp_time + period * np.arange(n)
        times = np.empty(2 * n + 2)
        times[0] = 0.0
        times[1:-1:2] = hold_starts
        times[2:-1:2] = hold_starts + self.hold_time
        times[-1] = n * period + self.ramp_time
        values = np.vstack([start, np.repeat(holds, 2, axis=0), end])
        for name, array in (('hold_pressures', holds), ('lower', lower), ('upper', upper),
                            ('start', start), ('end', end), ('knot_times', times),
                            ('_knot_values', values)):
            array = np.array(array)
            array.flags.writeable = False
            setattr(self, name, array)

    def __repr__(self):
        """Summarise the program."""
        return (f'ExcitationProgram({len(self.labels)} holds of {self.hold_time:g} s, ramps of '
                f'{self.ramp_time:g} s, {self.duration:g} s)')

    @property
    def n_holds(self):
        """Return the number of holds ``n``."""
        return len(self.labels)

    @property
    def duration(self):
        """Return the program's duration [s]: ``(n + 1) ramp_time + n hold_time``."""
        return float(self.knot_times[-1])

    @property
    def holds(self):
        """
        Return the holds as ``(start [s], end [s], pressures (m,) [Pa])``, in time order.

        Returns
        -------
        list of tuple
            One entry per hold.

        """
        return [(float(self.knot_times[1 + 2 * i]), float(self.knot_times[2 + 2 * i]),
                 self.hold_pressures[i]) for i in range(self.n_holds)]

    def pressures_at(self, t):
        """
        Return the actuation at time ``t`` (linear between the corners, see the module).

        Parameters
        ----------
        t : float or (N,) array_like  [s]
            Time since the program started; before 0 the start actuation, after
            :attr:`duration` the end actuation.

        Returns
        -------
        (m,) or (N, m) ndarray  [Pa]
            Within the bounds.

        Raises
        ------
        ValueError
            If a time is not finite.

        """
        t = np.asarray(t, dtype=float)
        if not np.all(np.isfinite(t)):
            raise ValueError('time must be finite')
        times, values = self.knot_times, self._knot_values
        flat = t.reshape(-1)
        k = np.clip(np.searchsorted(times, flat, side='right') - 1, 0, times.size - 2)
        w = np.clip((flat - times[k]) / (times[k + 1] - times[k]), 0.0, 1.0)[:, None]
        out = values[k] + w * (values[k + 1] - values[k])
        # a convex combination of in-bounds values; the clip only removes round-off overshoot
        out = np.clip(out, self.lower, self.upper)
        return out[0] if t.ndim == 0 else out.reshape(t.shape + (self.lower.size,))

    def finished(self, t):
        """
        Return whether the program has ended at time ``t`` [s].

        Within the clock's resolution (1 ns) of :attr:`duration` is the end: durations are sums
        of floats (3 x 0.2 + 4 x 0.1 s is 1 s + 2e-16 s).
        """
        return float(t) >= self.duration - 1e-9

    def hold_index(self, t):
        """
        Return the index of the hold that time ``t`` [s] lies in, or -1 (a ramp, before, after).

        Parameters
        ----------
        t : float  [s]
            Time since the program started.

        Returns
        -------
        int
            0 <= i < n inside hold i (its start and end included), else -1.

        """
        t = float(t)
        k = int(np.searchsorted(self.knot_times, t, side='right')) - 1
        if 1 <= k <= 2 * self.n_holds and k % 2 == 1:
            return (k - 1) // 2
        if k >= 2 and k % 2 == 0 and t == self.knot_times[k]:
            return (k - 2) // 2     # the end instant of hold (k - 2) / 2
        return -1
