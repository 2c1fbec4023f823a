"""
Read the package's YAML files so that every mistake becomes one :class:`ConfigError`.

:func:`read_yaml` (:func:`read_text` then :func:`parse_yaml`) turns a missing file, an unreadable
one, a YAML syntax error (with its line) or a wrong top-level type into
``ConfigError(path, key, problem)``; :class:`Section` reads typed keys from a parsed mapping and
names the dotted key of whatever is missing or wrong (``chain.sections[1].count: must be an
integer, got str 'eight'``). A key a file may not hold is an error too (:func:`unknown_key`,
:meth:`Section.only`: ``gravty: unknown key, did you mean 'gravity'?``). Scene, segment, geometry,
params, camera and rig files all go through here.
"""

import difflib
import math
from pathlib import Path

from cbha_inverse.errors import ConfigError
import yaml

_MISSING = object()
_KIND_NAMES = {dict: 'mapping of keys', list: 'list'}


# libyaml's safe loader (same documents and error marks, ~10x faster: scene files and the
# segment compliances are read at every load, e.g. at each step of cbha_identify's fit)
_SAFE_LOADER = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)


def read_text(path):
    """
    Read a configuration file as text.

    Parameters
    ----------
    path : str or os.PathLike
        The file.

    Returns
    -------
    str
        Its contents (UTF-8).

    Raises
    ------
    ConfigError
        If the file is missing or unreadable (key ``file``).

    """
    path = Path(path)
    try:
        return path.read_text(encoding='utf-8')
    except FileNotFoundError:
        raise ConfigError(path, 'file', 'no such file') from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(path, 'file', f'cannot be read ({exc})') from None


def parse_yaml(text, path, *, expect=dict):
    """
    Parse the YAML text of a configuration file.

    Parameters
    ----------
    text : str
        The YAML document.
    path : str or os.PathLike
        The file it comes from (named in errors).
    expect : type
        Required type of the top-level value (``dict`` by default).

    Returns
    -------
    object
        The parsed document.

    Raises
    ------
    ConfigError
        If the text is not valid YAML (key ``line N``) or its top level is not an ``expect``.

    """
    try:
        data = yaml.load(text, Loader=_SAFE_LOADER)
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f'line {mark.line + 1}' if mark is not None else 'yaml'
        problem = ' '.join(str(part) for part in (getattr(exc, 'context', None),
                                                  getattr(exc, 'problem', None)) if part)
        raise ConfigError(path, where, f'invalid YAML: {problem or exc}') from None
    if not isinstance(data, expect):
        raise ConfigError(path, 'top level', f'must be a {_KIND_NAMES.get(expect, expect)}, got '
                          f'{_describe(data)}')
    return data


def read_yaml(path, *, expect=dict):
    """
    Parse a YAML file: :func:`parse_yaml` of :func:`read_text`.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    expect : type
        Required type of the top-level value (see :func:`parse_yaml`).

    Returns
    -------
    object
        The parsed document, of type ``expect``.

    Raises
    ------
    ConfigError
        If the file is missing or unreadable (key ``file``), not valid YAML (key ``line N``) or
        of another top-level type (key ``top level``).

    """
    return parse_yaml(read_text(path), path, expect=expect)


def unknown_key(name, known, what='key'):
    """
    Say that a key is not one of those a file may hold, naming the nearest valid one.

    Parameters
    ----------
    name : object
        The key found.
    known : iterable of str
        The valid keys there.
    what : str
        What a key is there (``'parameter of inverse_solver'``).

    Returns
    -------
    str
        ``unknown key, did you mean 'gravity'?`` (the nearest, by
        :func:`difflib.get_close_matches`), or ``unknown key (valid: ...)`` when none is near.

    """
    known = sorted(str(k) for k in known)
    near = nearest(name, known)
    if near is not None:
        return f'unknown {what}, did you mean {near!r}?'
    return f"unknown {what} (valid: {', '.join(known) or 'none'})"


def nearest(name, known):
    """Return the name of ``known`` nearest to ``name`` (:mod:`difflib`), or None if none is."""
    near = difflib.get_close_matches(str(name), [str(k) for k in known], n=1, cutoff=0.6)
    return near[0] if near else None


def check_keys(path, mapping, known, where=''):
    """
    Raise a :class:`ConfigError` for the first key of ``mapping`` that is not in ``known``.

    Parameters
    ----------
    path : str or os.PathLike
        The file (named in the error).
    mapping : dict
        The parsed mapping.
    known : iterable of str
        The keys it may hold.
    where : str
        Dotted key of the mapping in the file ('' at the top level).

    Raises
    ------
    ConfigError
        ``<file>: <where.key>: unknown key, did you mean '<nearest>'?``.

    """
    known = set(known)
    for key in mapping:
        if key not in known:
            raise ConfigError(path, f'{where}.{key}' if where else str(key),
                              unknown_key(key, known))


def _describe(value):
    """Name a YAML value for a message."""
    if value is None:
        return 'nothing (empty)'
    if isinstance(value, dict):
        return 'a mapping'
    if isinstance(value, list):
        return f'a list of {len(value)}'
    return f'{type(value).__name__} {value!r}'


class Section:
    """
    A mapping read from a configuration file, with its place in the file for error messages.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    data : object
        The parsed value (must be a mapping).
    where : str
        Dotted key of this mapping in the file ('' at the top level).

    Raises
    ------
    ConfigError
        If ``data`` is not a mapping.

    """

    def __init__(self, path, data, where=''):
        """Check that ``data`` is a mapping."""
        self.path = Path(path)
        self.where = where
        if not isinstance(data, dict):
            raise ConfigError(self.path, where or 'top level',
                              f'must be a mapping of keys, got {_describe(data)}')
        self.data = data

    def only(self, *known):
        """Return this section after checking that it holds no other key (:func:`check_keys`)."""
        check_keys(self.path, self.data, known, self.where)
        return self

    def key(self, name):
        """Return the dotted key of ``name`` in this section."""
        return f'{self.where}.{name}' if self.where else str(name)

    def error(self, name, problem):
        """Return a ``ConfigError`` about key ``name`` of this section."""
        return ConfigError(self.path, self.key(name), problem)

    def has(self, name):
        """Return whether the key is present (and not null)."""
        return self.data.get(name) is not None

    def _raw(self, name, default):
        value = self.data.get(name)
        if value is None:
            if default is _MISSING:
                raise self.error(name, 'missing')
            return default, False
        return value, True

    def number(self, name, default=_MISSING, *, positive=False, minimum=None):
        """Return a finite float (optionally > 0 or >= ``minimum``)."""
        value, given = self._raw(name, default)
        if not given:
            return value
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(name, f'must be a number, got {_describe(value)}')
        value = float(value)
        if not math.isfinite(value):
            raise self.error(name, f'must be finite, got {value}')
        if positive and value <= 0.0:
            raise self.error(name, f'must be > 0, got {value:g}')
        if minimum is not None and value < minimum:
            raise self.error(name, f'must be >= {minimum:g}, got {value:g}')
        return value

    def integer(self, name, default=_MISSING, *, minimum=None):
        """Return an int (optionally >= ``minimum``)."""
        value, given = self._raw(name, default)
        if not given:
            return value
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(name, f'must be an integer, got {_describe(value)}')
        if minimum is not None and value < minimum:
            raise self.error(name, f'must be >= {minimum}, got {value}')
        return value

    def text(self, name, default=_MISSING, *, choices=None):
        """Return a string (optionally one of ``choices``)."""
        value, given = self._raw(name, default)
        if not given:
            return value
        if not isinstance(value, str):
            raise self.error(name, f'must be a string, got {_describe(value)}')
        if choices is not None and value not in choices:
            raise self.error(name, f'must be one of {list(choices)}, got {value!r}')
        return value

    def vector(self, name, size, default=_MISSING):
        """Return a tuple of ``size`` finite floats."""
        value, given = self._raw(name, default)
        if not given:
            return value
        if (not isinstance(value, list) or len(value) != size or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                for v in value)):
            raise self.error(name, f'must be a list of {size} finite numbers, got '
                             f'{_describe(value)}')
        return tuple(float(v) for v in value)

    def section(self, name, default=_MISSING):
        """Return the sub-mapping ``name`` as a ``Section``."""
        value, given = self._raw(name, default)
        return Section(self.path, value, self.key(name)) if given else value

    def sections(self, name, default=_MISSING):
        """Return the list of mappings ``name`` as ``Section`` objects."""
        value, given = self._raw(name, default)
        if not given:
            return value
        if not isinstance(value, list):
            raise self.error(name, f'must be a list, got {_describe(value)}')
        return [Section(self.path, item, f'{self.key(name)}[{i}]') for i, item in enumerate(value)]


def read_section(path):
    """Parse a YAML mapping file and return it as the top-level :class:`Section`."""
    return Section(path, read_yaml(path))
