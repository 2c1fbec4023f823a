"""
Custom excitation programs: the holds read from a YAML file.

The format (:func:`read_program_file`)::

    holds:
      - [150000.0, 0.0, 0.0, 75000.0, 75000.0, 75000.0]    # scene actuator order, Pa
      - {inner_over: 0.0, inner_right: 150000.0, inner_left: 0.0,
         outer_over: 75000.0, outer_right: 75000.0, outer_left: 75000.0}   # by name, all of them
    description: text                                      # optional

Every value must lie within the actuator bounds; an error names the file and the key.
"""

import math
from pathlib import Path

from cbha_inverse.config_files import read_yaml, Section
from cbha_inverse.errors import ConfigError
from cbha_inverse.identify.excitation.program import check_bounds
from cbha_inverse.paths import config_path
import numpy as np

_FILE_KEYS = ('holds', 'description')


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
    lower, upper = check_bounds(lower, upper)
    names = list(actuator_names)
    top = Section(path, read_yaml(path)).only(*_FILE_KEYS)
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
