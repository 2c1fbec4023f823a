r"""
Excitation programs for identification: pressure holds joined by linear ramps (no ROS).

From a circle lap alone the outer section's absolute stiffness is weakly determined (issue 17):
holding each section bent to its extremes for a few seconds pins it. A program is a list of
*holds* (one actuation vector each, held for ``hold_time``), entered from a ``start`` actuation
and left to an ``end`` actuation; consecutive set-points are joined by linear ramps of
``ramp_time``, so a real arm never sees a step::

    actuation
      ^        hold 0            hold 1                   hold n-1
      |      ________          ________                 ________
      |     /        \        /        \     ...       /        \
      |____/          \______/          \____  ...  __/          \____ end
      +----+--------+---------+--------+----------------------------+----> t
      0    r      r + h    2r + h   2r + 2h                 (n + 1) r + n h = duration

Named programs of a scene whose actuators are grouped by chain section
(:attr:`cbha_inverse.scene.Scene.actuator_sections`, e.g. the CBHA's inner and outer tubes):

- ``<section>_bends`` (``outer_bends``, ``inner_bends``): for each actuator k of that section, k
  at its upper bound, the section's other actuators at their lower bounds, every other
  actuator at mid range;
- ``bends``: the bends of every section, in chain order;
- ``extension``: every actuator at the fractions :data:`EXTENSION_FRACTIONS` of its range;
- ``all``: ``extension`` then ``bends``.

A custom program is a YAML file (:func:`read_program_file`)::

    holds:
      - [150000.0, 0.0, 0.0, 75000.0, 75000.0, 75000.0]    # scene actuator order, Pa
      - {inner_over: 0.0, inner_right: 150000.0, inner_left: 0.0,
         outer_over: 75000.0, outer_right: 75000.0, outer_left: 75000.0}   # by name, all of them

Every hold, the start and the end must lie within the actuator bounds. Units are those of the
actuators: gauge Pa for cavities (N for cables).
"""

import math
from pathlib import Path

from cbha_inverse.config_files import read_yaml, Section
from cbha_inverse.errors import ConfigError
from cbha_inverse.paths import config_path
import numpy as np

EXTENSION_FRACTIONS = (0.0, 0.25, 0.5, 0.75, 1.0)
"""Fractions of each actuator's range held by the ``extension`` program."""

DEFAULT_HOLD_TIME = 3.0
"""Default hold duration [s] (a few seconds: the arm settles, the samples are quasi-static)."""

DEFAULT_RAMP_TIME = 1.0
"""Default ramp duration [s] between two set-points."""

_FILE_KEYS = ('holds', 'description')


def _time(value, name):
    """Return a finite positive duration [s] or raise ``ValueError`` naming it."""
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ValueError(f'{name} must be a number of seconds, got {value!r}') from None
    if not math.isfinite(value) or value <= 0.0:
        raise ValueError(f'{name} must be a finite number of seconds > 0, got {value}')
    return value


def _bounds(lower, upper):
    """Return the validated bounds as two (m,) float arrays."""
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
    lower, upper = _bounds(lower, upper)
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
        lower, upper = _bounds(lower, upper)
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


def section_groups(actuator_sections):
    """
    Group actuators by chain section.

    Parameters
    ----------
    actuator_sections : sequence of (str or None)
        The section of each actuator (:attr:`cbha_inverse.scene.Scene.actuator_sections`).

    Returns
    -------
    dict of str to tuple of int
        Section -> its actuators' indices, sections in order of first appearance.

    """
    groups = {}
    for k, section in enumerate(actuator_sections):
        if section is not None:
            groups.setdefault(section, []).append(k)
    return {name: tuple(indices) for name, indices in groups.items()}


def bend_holds(lower, upper, groups, sections=None, names=None):
    """
    Return the holds that bend each section to its extremes, one actuator at a time.

    For each section s (in order) and each actuator k of s: k at its upper bound, the other
    actuators of s at their lower bounds, every actuator outside s at mid range.

    Parameters
    ----------
    lower, upper : (m,) array_like  [Pa]
        Actuator bounds.
    groups : mapping of str to sequence of int
        Section -> actuator indices (:func:`section_groups`).
    sections : sequence of str, optional
        The sections to bend (default: all of ``groups``, in its order).
    names : sequence of str, optional
        Actuator names for the labels (default ``'actuator k'``).

    Returns
    -------
    holds : (n, m) ndarray  [Pa]
    labels : tuple of str

    """
    lower, upper = _bounds(lower, upper)
    mid = 0.5 * (lower + upper)
    sections = list(groups) if sections is None else list(sections)
    rows, labels = [], []
    for section in sections:
        members = np.asarray(groups[section], dtype=int)
        for k in members:
            row = mid.copy()
            row[members] = lower[members]
            row[k] = upper[k]
            rows.append(row)
            label = names[k] if names is not None else f'actuator {k}'
            labels.append(f'{section} bend: {label} max, other {section} min, rest mid')
    if not rows:
        raise ValueError('no section with actuators to bend')
    return np.array(rows), tuple(labels)


def extension_holds(lower, upper, fractions=EXTENSION_FRACTIONS):
    """
    Return the holds of a pure extension: every actuator at the same fraction of its range.

    Parameters
    ----------
    lower, upper : (m,) array_like  [Pa]
        Actuator bounds.
    fractions : sequence of float
        Fractions in [0, 1], one hold each.

    Returns
    -------
    holds : (len(fractions), m) ndarray  [Pa]
        ``lower + f (upper - lower)``.
    labels : tuple of str

    """
    lower, upper = _bounds(lower, upper)
    fractions = np.asarray(fractions, dtype=float).reshape(-1)
    if fractions.size == 0 or not np.all((fractions >= 0.0) & (fractions <= 1.0)):
        raise ValueError(f'fractions must lie in [0, 1], got {fractions.tolist()}')
    holds = lower + fractions[:, None] * (upper - lower)
    return holds, tuple(f'extension: every actuator at {f:g} of its range' for f in fractions)


def program_names(actuator_sections):
    """
    Return the named programs available for a scene.

    Parameters
    ----------
    actuator_sections : sequence of (str or None)
        The section of each actuator.

    Returns
    -------
    tuple of str
        ``'extension'``, and with sections ``'bends'``, ``'all'`` and one
        ``'<section>_bends'`` per section.

    """
    sections = tuple(section_groups(actuator_sections))
    if not sections:
        return ('extension',)
    return ('all', 'bends', 'extension') + tuple(f'{s}_bends' for s in sections)


def named_holds(name, lower, upper, actuator_sections, names=None):
    """
    Return the holds of a named program (see the module).

    Parameters
    ----------
    name : str
        One of :func:`program_names`.
    lower, upper : (m,) array_like  [Pa]
        Actuator bounds.
    actuator_sections : sequence of (str or None)
        The section of each actuator.
    names : sequence of str, optional
        Actuator names, for the labels.

    Returns
    -------
    holds : (n, m) ndarray  [Pa]
    labels : tuple of str

    Raises
    ------
    ValueError
        If ``name`` is not a program of this scene.

    """
    known = program_names(actuator_sections)
    if name not in known:
        raise ValueError(f'unknown excitation program {name!r} (this scene has {list(known)}, '
                         'or give a YAML file of holds)')
    groups = section_groups(actuator_sections)
    if name == 'extension':
        return extension_holds(lower, upper)
    if name == 'bends':
        return bend_holds(lower, upper, groups, names=names)
    if name == 'all':
        extension, extension_labels = extension_holds(lower, upper)
        bends, bend_labels = bend_holds(lower, upper, groups, names=names)
        return np.vstack([extension, bends]), extension_labels + bend_labels
    return bend_holds(lower, upper, groups, [name[:-len('_bends')]], names=names)


def _number(path, key, value):
    """Return a finite pressure read from a program file, or raise a ``ConfigError``."""
    if isinstance(value, str):
        try:
            float(value)
            hint = (' (YAML reads exponent notation as a number only with a decimal point and '
                    'a signed exponent: write 1.5e+5 or 150000.0)')
        except ValueError:
            hint = ''
        raise ConfigError(path, key, f'must be a number, got text {value!r}{hint}')
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(path, key, f'must be a number, got {value!r}')
    if not math.isfinite(value):
        raise ConfigError(path, key, f'must be finite, got {value}')
    return float(value)


def read_program_file(path, actuator_names, lower, upper):
    """
    Read the holds of a custom program from YAML (format in the module docstring).

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    actuator_names : sequence of str
        Scene actuator order.
    lower, upper : (m,) array_like  [Pa]
        Bounds every value must lie within.

    Returns
    -------
    holds : (n, m) ndarray  [Pa]
        Scene actuator order.
    labels : tuple of str

    Raises
    ------
    cbha_inverse.errors.ConfigError
        Naming the file and the key (``holds[2]``, ``holds[2].outer_left``, ``holds[0][3]``)
        of what is missing, malformed, not finite or outside the bounds.

    """
    lower, upper = _bounds(lower, upper)
    names = list(actuator_names)
    top = Section(path, read_yaml(path))
    for key in top.data:
        if key not in _FILE_KEYS:
            raise top.error(key, f'unknown key (known: {list(_FILE_KEYS)})')
    if top.has('description'):
        top.text('description')
    items = top.data.get('holds')
    if not isinstance(items, list) or not items:
        raise top.error('holds', 'must be a non-empty list of holds (each a list of '
                        f'{len(names)} pressures in scene order {names}, or a mapping by '
                        'actuator name)')
    rows = []
    for i, item in enumerate(items):
        where = f'holds[{i}]'
        if isinstance(item, dict):
            unknown = [k for k in item if k not in names]
            if unknown:
                raise ConfigError(path, f'{where}.{unknown[0]}', f'no actuator {unknown[0]!r} '
                                  f'(the scene has {names})')
            missing = [n for n in names if n not in item]
            if missing:
                raise ConfigError(path, where, f'misses actuators {missing} (give every '
                                  'actuator)')
            keys = [f'{where}.{n}' for n in names]
            row = np.array([_number(path, key, item[n]) for key, n in zip(keys, names)])
        elif isinstance(item, list):
            if len(item) != len(names):
                raise ConfigError(path, where, f'must be a list of {len(names)} pressures '
                                  f'(scene order {names}), got {len(item)} values')
            keys = [f'{where}[{k}]' for k in range(len(names))]
            row = np.array([_number(path, key, v) for key, v in zip(keys, item)])
        else:
            raise ConfigError(path, where, f'must be a list of {len(names)} pressures or a '
                              f'mapping by actuator name, got {item!r}')
        for k, value in enumerate(row):
            if not lower[k] <= value <= upper[k]:
                raise ConfigError(path, keys[k], f'{value:g} is outside the bounds '
                                  f'[{lower[k]:g}, {upper[k]:g}] of {names[k]}')
        rows.append(row)
    return np.array(rows), tuple(f'{Path(path).name} hold {i}' for i in range(len(rows)))


def is_program_file(program):
    """Return whether a program name denotes a YAML file (``.yaml`` / ``.yml``)."""
    return Path(str(program)).suffix in ('.yaml', '.yml')


def resolve_program_file(program):
    """
    Return the path of a program file: as given, else relative to the package's ``config/``.

    Parameters
    ----------
    program : str or os.PathLike
        E.g. ``/home/me/holds.yaml`` or ``excitation/cbha_example.yaml``.

    Returns
    -------
    pathlib.Path
        The existing file, or the path as given when neither exists (reading it then reports
        the missing file).

    """
    path = Path(program)
    if path.is_file() or path.is_absolute():
        return path
    shipped = config_path(str(program))
    return shipped if shipped.is_file() else path


def driver_bounds(scene, max_pressure=None):
    """
    Return a scene's actuator bounds as a valve driver accepts them.

    Parameters
    ----------
    scene : cbha_inverse.scene.Scene
        Its ``lower_bounds`` and ``upper_bounds``.
    max_pressure : float, optional  [Pa]
        The driver's limit (``cbha_excite`` / ``cbha_sim`` ``max_pressure``); None: no cap.

    Returns
    -------
    lower, upper : (m,) ndarray  [Pa]
        ``max(lower, 0)`` and ``min(upper, max_pressure)``.

    Raises
    ------
    ValueError
        If the cap lies below a lower bound.

    """
    lower = np.maximum(np.asarray(scene.lower_bounds, dtype=float), 0.0)
    upper = np.asarray(scene.upper_bounds, dtype=float)
    if max_pressure is not None:
        upper = np.minimum(upper, float(max_pressure))
    if np.any(lower > upper):
        raise ValueError(f'max_pressure {max_pressure:g} Pa is below a lower actuator bound of '
                         'the scene')
    return lower, upper


def make_program(scene, program, *, hold_time=DEFAULT_HOLD_TIME, ramp_time=DEFAULT_RAMP_TIME,
                 start=None, end=None, max_pressure=None):
    """
    Build a named or custom excitation program for a scene.

    Parameters
    ----------
    scene : cbha_inverse.scene.Scene
        Its ``actuator_names``, ``actuator_sections`` and bounds are used.
    program : str or os.PathLike
        A name of :func:`program_names` or a YAML file of holds (``.yaml``/``.yml``: a path, or
        relative to the package's ``config/``, e.g. ``excitation/cbha_example.yaml``).
    hold_time, ramp_time : float  [s]
        See :class:`ExcitationProgram`.
    start, end : (m,) array_like, optional  [Pa]
        Scene order (default mid range).
    max_pressure : float, optional  [Pa]
        A valve driver's limit: the bounds are then :func:`driver_bounds` (the named programs
        span them, a file's values must lie within them).

    Returns
    -------
    ExcitationProgram

    Raises
    ------
    ValueError
        On an unknown program name, invalid times, start or end, or a ``max_pressure`` below
        a lower bound.
    cbha_inverse.errors.ConfigError
        On a bad program file (file and key named).

    """
    lower, upper = driver_bounds(scene, max_pressure)
    if is_program_file(program):
        holds, labels = read_program_file(resolve_program_file(program), scene.actuator_names,
                                          lower, upper)
    else:
        holds, labels = named_holds(str(program), lower, upper, scene.actuator_sections,
                                    scene.actuator_names)
    return ExcitationProgram(holds, lower, upper, hold_time=hold_time, ramp_time=ramp_time,
                             start=start, end=end, labels=labels)
