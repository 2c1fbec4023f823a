"""
Repair the exported CMake files of the ROS 2 interface wheels from PyPI (idempotent).

The ``ros-jazzy-*`` message wheels ship CMake export files
(``share/<pkg>/cmake/export_<pkg>__rosidl_generator_pyExport.cmake``) whose
``INTERFACE_INCLUDE_DIRECTORIES`` name the Python and numpy include folders of the machine that
built the wheels (``/opt/python/cp311-cp311/include/python3.11`` and its numpy
``_core/include``). CMake refuses an imported target whose include folder does not exist, so any
interface package that depends on those messages (``builtin_interfaces`` for a stamp) fails to
configure. :func:`repair_exports` rewrites each such missing folder to the running interpreter's
own (``sysconfig`` include folder, ``numpy.get_include()``); folders that exist are left alone,
so a second run changes nothing. Only files under the given prefix are touched.

Command line: ``python -m cbha_inverse.interfaces.rosidl_exports [PREFIX]`` (default: this
interpreter's ``sys.prefix``, i.e. the venv); it prints what it changed.
"""

import argparse
from dataclasses import dataclass
import os
from pathlib import Path
import re
import sys
import sysconfig

from cbha_inverse.errors import report_config_error

EXPORT_GLOB = 'share/*/cmake/*Export.cmake'
"""Where the exported CMake targets of installed ROS packages live under a prefix."""

_INCLUDE_LIST = re.compile(r'(INTERFACE_INCLUDE_DIRECTORIES ")([^"]*)(")')


@dataclass(frozen=True)
class ExportRepair:
    """
    What :func:`repair_exports` did.

    Attributes
    ----------
    scanned : int
        Export files read.
    rewritten : tuple of str
        Files whose include list was rewritten.
    unresolved : tuple of str
        Missing include folders that neither rule maps (left as they are).

    """

    scanned: int
    rewritten: tuple
    unresolved: tuple


def interpreter_includes():
    """
    Return the include folders of the running interpreter and of its numpy.

    Returns
    -------
    python_include : str
        ``sysconfig.get_paths()['include']`` (``Python.h``).
    numpy_include : str or None
        ``numpy.get_include()``, or None when numpy is not installed.

    """
    try:
        import numpy
    except ImportError:
        numpy_include = None
    else:
        numpy_include = numpy.get_include()
    return sysconfig.get_paths()['include'], numpy_include


def replacement_for(folder, python_include, numpy_include):
    """
    Return the local folder that stands for a missing include folder of the wheel builder.

    Parameters
    ----------
    folder : str
        A folder named in an export file.
    python_include : str
        This interpreter's include folder.
    numpy_include : str or None
        This interpreter's numpy include folder.

    Returns
    -------
    str or None
        ``python_include`` for a ``.../include/python3.X`` folder, ``numpy_include`` for a
        ``.../numpy/_core/include`` (or ``numpy/core/include``) folder, None otherwise.

    """
    normalized = folder.replace('\\', '/').rstrip('/')
    if re.search(r'/include/python3\.\d+$', normalized):
        return python_include
    if numpy_include and re.search(r'/numpy/(_core|core)/include$', normalized):
        return numpy_include
    return None


def _missing(folder):
    """Return whether an include folder named in an export file does not exist here."""
    return bool(folder) and '$' not in folder and not os.path.isdir(folder)


def broken_exports(prefix):
    """
    Return the export files under a prefix that name a missing Python or numpy include folder.

    Parameters
    ----------
    prefix : str or os.PathLike
        Install prefix (the venv).

    Returns
    -------
    list of str
        The files that :func:`repair_exports` would rewrite.

    """
    python_include, numpy_include = interpreter_includes()
    broken = []
    for path in sorted(Path(prefix).glob(EXPORT_GLOB)):
        folders = [folder for match in _INCLUDE_LIST.finditer(path.read_text())
                   for folder in match.group(2).split(';')]
        if any(_missing(f) and replacement_for(f, python_include, numpy_include) for f in folders):
            broken.append(str(path))
    return broken


def repair_exports(prefix, python_include=None, numpy_include=None):
    """
    Rewrite missing Python/numpy include folders in a prefix's CMake export files.

    Parameters
    ----------
    prefix : str or os.PathLike
        Install prefix of the wheels (the venv: ``sys.prefix``).
    python_include, numpy_include : str, optional
        Replacement folders (default: :func:`interpreter_includes`).

    Returns
    -------
    ExportRepair
        Files scanned and rewritten, and missing folders that no rule maps.

    """
    if python_include is None:
        python_include, numpy_include = interpreter_includes()
    rewritten, unresolved = [], set()
    paths = sorted(Path(prefix).glob(EXPORT_GLOB))

    def rewrite(match):
        folders = []
        for folder in match.group(2).split(';'):
            if _missing(folder):
                local = replacement_for(folder, python_include, numpy_include)
                if local is None:
                    unresolved.add(folder)
                else:
                    folder = local
            folders.append(folder)
        return match.group(1) + ';'.join(folders) + match.group(3)

    for path in paths:
        text = path.read_text()
        repaired = _INCLUDE_LIST.sub(rewrite, text)
        if repaired != text:
            path.write_text(repaired)
            rewritten.append(str(path))
    return ExportRepair(len(paths), tuple(rewritten), tuple(sorted(unresolved)))


def main(argv=None):
    """
    Repair the export files of a prefix; print a one-line summary.

    Parameters
    ----------
    argv : list of str, optional
        Command-line arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        0 on success, 2 when the prefix is not a folder.

    """
    parser = argparse.ArgumentParser(
        prog='python -m cbha_inverse.interfaces.rosidl_exports', description=__doc__.split(
            '\n\n')[0].strip(), formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('prefix', nargs='?', default=sys.prefix,
                        help='install prefix of the ROS wheels (default: %(default)s)')
    args = parser.parse_args(argv)
    if not Path(args.prefix).is_dir():
        return report_config_error('rosidl_exports', f'{args.prefix}: not a folder')
    result = repair_exports(args.prefix)
    print(f'rosidl exports under {args.prefix}: {result.scanned} scanned, '
          f"{len(result.rewritten)} rewritten to this interpreter's include folders"
          + (f'; left unresolved: {", ".join(result.unresolved)}' if result.unresolved else ''))
    return 0


if __name__ == '__main__':
    sys.exit(main())
