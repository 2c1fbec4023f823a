"""Locate the package's data (config/, meshes/) in a colcon install or in a source checkout."""

from pathlib import Path

PACKAGE_NAME = 'cbha_inverse'


def share_dir():
    """
    Return the directory that holds ``config/`` and ``meshes/``.

    Returns
    -------
    pathlib.Path
        ``<prefix>/share/cbha_inverse`` when the package is installed by colcon (found through the
        ament index), otherwise the source checkout that contains this module.

    Raises
    ------
    FileNotFoundError
        If neither location holds a ``config`` directory.

    """
    source_root = Path(__file__).resolve().parents[1]
    if (source_root / 'config').is_dir() and (source_root / 'package.xml').is_file():
        return source_root
    try:
        from ament_index_python.packages import get_package_share_directory
        installed = Path(get_package_share_directory(PACKAGE_NAME))
    except (ImportError, LookupError, ValueError):
        installed = None
    if installed is not None and (installed / 'config').is_dir():
        return installed
    raise FileNotFoundError(
        f'cannot find the data of {PACKAGE_NAME}: no config/ beside {source_root} and the '
        'package is not in the ament index (source install/setup.sh of your colcon workspace)')


def config_path(*parts):
    """
    Return a path under the package's ``config/`` directory.

    Parameters
    ----------
    *parts : str
        Path components below ``config/``, e.g. ``('scenes', 'cbha.yaml')``.

    Returns
    -------
    pathlib.Path
        The joined path (it need not exist).

    """
    return share_dir().joinpath('config', *parts)


def meshes_path(*parts):
    """
    Return a path under the package's ``meshes/`` directory.

    Parameters
    ----------
    *parts : str
        Path components below ``meshes/``.

    Returns
    -------
    pathlib.Path
        The joined path (it need not exist).

    """
    return share_dir().joinpath('meshes', *parts)
