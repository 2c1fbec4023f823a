"""
Mapping of our pressure command to the Robotino driver's 8-channel bar array.

See ``docs/own-robot.md`` for running the arm through the driver.

The existing ROS 2 driver of the Robotino XT (``robotino_node``) subscribes to
``set_bha_pressures``: exactly 8 set-points in bar, channels 0-2 the inner (proximal) section's
tubes over / right / left, 3-5 the outer (distal) section's, 6-7 the wrist (rotate horizontal,
vertical). Our package commands 6 gauge pressures in Pa in the order of the ``valve_names``
parameter. :func:`robotino_bar_command` converts one to the other; it is NaN-safe (a non-finite
value vents that channel), never exceeds the 1.5 bar ceiling used in practice (the authors' own
SOFA controller uses the same cap) and sets the wrist channels to fixed set-points (default 0).
The driver publishes ``bha_readings`` with the measured pressures in bar in the same channel order;
:func:`robotino_pressures` maps them back to gauge Pa in ``valve_names`` order.
"""

import numpy as np

N_CHANNELS = 8
"""Channels of the vendor API."""

PASCAL_PER_BAR = 1.0e5
"""1 bar = 1e5 Pa."""

MAX_BAR = 1.5
"""Pressure ceiling used in practice [bar] (150 kPa gauge)."""

CHANNELS = {'inner_over': 0, 'inner_right': 1, 'inner_left': 2,
            'outer_over': 3, 'outer_right': 4, 'outer_left': 5,
            'wrist_horizontal': 6, 'wrist_vertical': 7}
"""Vendor channel of each named valve."""

ARM_VALVES = ('inner_over', 'inner_right', 'inner_left', 'outer_over', 'outer_right', 'outer_left')
"""The 6 arm valves in vendor channel order (our default ``valve_names``)."""

WRIST_VALVES = ('wrist_horizontal', 'wrist_vertical')
"""The 2 wrist channels (6, 7) in vendor order."""


def _check_valve_names(names):
    """Raise ValueError on valve names that are unknown or repeated."""
    unknown = [name for name in names if name not in CHANNELS]
    if unknown:
        raise ValueError(f'unknown valve names {unknown}; known: {sorted(CHANNELS)}')
    if len(set(names)) != len(names):
        raise ValueError(f'duplicate valve names in {list(names)}')


def robotino_bar_command(pressures, valve_names=ARM_VALVES, max_bar=MAX_BAR,
                         wrist_bar=(0.0, 0.0)):
    """
    Convert gauge pressures [Pa] to the Robotino driver's 8-channel bar array.

    Parameters
    ----------
    pressures : (m,) array_like  [Pa]
        Gauge pressures in the order of ``valve_names`` (m <= 8).
    valve_names : sequence of str
        Names of the commanded valves, each a key of :data:`CHANNELS` (no duplicates).
    max_bar : float  [bar]
        Ceiling (at most :data:`MAX_BAR`).
    wrist_bar : (2,) array_like  [bar]
        Set-points of the wrist channels 6 and 7 when ``valve_names`` does not command them
        (clipped like the others; a non-finite value gives 0).

    Returns
    -------
    (8,) ndarray  [bar]
        Set-points per vendor channel: ``clip(p / 1e5, 0, max_bar)``, 0 for a non-finite value
        and for every arm channel not commanded, ``wrist_bar`` on the wrist channels not
        commanded.

    Raises
    ------
    ValueError
        On unknown or duplicate valve names, a length mismatch, a ceiling outside
        ``[0, MAX_BAR]`` or a ``wrist_bar`` that is not 2 values.

    """
    pressures = np.asarray(pressures, dtype=float).reshape(-1)
    names = tuple(valve_names)
    if pressures.size != len(names):
        raise ValueError(f'{pressures.size} pressures for {len(names)} valve names')
    _check_valve_names(names)
    if not 0.0 <= max_bar <= MAX_BAR:
        raise ValueError(f'max_bar must lie in [0, {MAX_BAR}], got {max_bar}')
    wrist_bar = np.asarray(wrist_bar, dtype=float).reshape(-1)
    if wrist_bar.size != len(WRIST_VALVES):
        raise ValueError(f'wrist_bar must have {len(WRIST_VALVES)} values, got {wrist_bar.size}')
    command = np.zeros(N_CHANNELS)
    command[[CHANNELS[name] for name in WRIST_VALVES]] = np.clip(
        np.where(np.isfinite(wrist_bar), wrist_bar, 0.0), 0.0, max_bar)
    bar = np.where(np.isfinite(pressures), pressures, 0.0) / PASCAL_PER_BAR
    command[[CHANNELS[name] for name in names]] = np.clip(bar, 0.0, max_bar)
    return command


def robotino_pressures(channel_bar, valve_names=ARM_VALVES):
    """
    Convert the driver's measured channel pressures [bar] to gauge pressures [Pa] of our valves.

    Parameters
    ----------
    channel_bar : (c,) array_like  [bar]
        Pressures per vendor channel (``BHAReadings.pressures``), c > every channel named.
    valve_names : sequence of str
        Valves wanted, each a key of :data:`CHANNELS` (no duplicates).

    Returns
    -------
    (m,) ndarray  [Pa]
        ``channel_bar[channel of each valve] * 1e5`` in ``valve_names`` order (non-finite readings
        pass through for the caller to reject).

    Raises
    ------
    ValueError
        On unknown or duplicate valve names, or too few channels for them.

    """
    channel_bar = np.asarray(channel_bar, dtype=float).reshape(-1)
    names = tuple(valve_names)
    _check_valve_names(names)
    channels = [CHANNELS[name] for name in names]
    if channels and channel_bar.size <= max(channels):
        raise ValueError(f'{channel_bar.size} channels read, valve_names need '
                         f'{max(channels) + 1}')
    return channel_bar[channels] * PASCAL_PER_BAR


def string_pot_names(names, count):
    """
    Return the names of ``count`` string potentiometers (``BHAReadings.cablepull`` order).

    Parameters
    ----------
    names : sequence of str
        The configured names (``robotino_bridge`` ``string_pot_names``).
    count : int
        Potentiometers read.

    Returns
    -------
    tuple of str
        ``names[i]``, and ``'string_pot_<i>'`` beyond the configured ones.

    """
    return tuple(names[i] if i < len(names) else f'string_pot_{i}' for i in range(count))
