"""
Mapping of our pressure command to the Robotino driver's 8-channel bar array (notes/cbha.md).

The existing ROS 2 driver of the Robotino XT (``robotino_node``) subscribes to
``set_bha_pressures``: exactly 8 set-points in bar, channels 0-2 the inner (proximal) section's
tubes over / right / left, 3-5 the outer (distal) section's, 6-7 the wrist (rotate horizontal,
vertical). Our package commands 6 gauge pressures in Pa in the order of the ``valve_names``
parameter. :func:`robotino_bar_command` converts one to the other; it is NaN-safe (a non-finite
value vents that channel), never exceeds the 1.5 bar ceiling used in practice (the authors' own
SOFA controller uses the same cap) and leaves the wrist at 0.
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


def robotino_bar_command(pressures, valve_names=ARM_VALVES, max_bar=MAX_BAR):
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

    Returns
    -------
    (8,) ndarray  [bar]
        Set-points per vendor channel: ``clip(p / 1e5, 0, max_bar)``, 0 for a non-finite value
        and for every channel not commanded (the wrist).

    Raises
    ------
    ValueError
        On unknown or duplicate valve names, a length mismatch or a ceiling outside
        ``[0, MAX_BAR]``.

    """
    pressures = np.asarray(pressures, dtype=float).reshape(-1)
    names = tuple(valve_names)
    if pressures.size != len(names):
        raise ValueError(f'{pressures.size} pressures for {len(names)} valve names')
    unknown = [name for name in names if name not in CHANNELS]
    if unknown:
        raise ValueError(f'unknown valve names {unknown}; known: {sorted(CHANNELS)}')
    if len(set(names)) != len(names):
        raise ValueError(f'duplicate valve names in {list(names)}')
    if not 0.0 <= max_bar <= MAX_BAR:
        raise ValueError(f'max_bar must lie in [0, {MAX_BAR}], got {max_bar}')
    bar = np.where(np.isfinite(pressures), pressures, 0.0) / PASCAL_PER_BAR
    command = np.zeros(N_CHANNELS)
    command[[CHANNELS[name] for name in names]] = np.clip(bar, 0.0, max_bar)
    return command
