"""
Build an interface package shipped with cbha_inverse with colcon, and use it without sourcing.

The ROS 2 interface packages that are not on PyPI (``robotino_msgs``, ``tf2_msgs``) are shipped as
ament_cmake packages in this folder. :func:`build_interface_package` copies one into
``<workspace>/src/<package>`` and builds it (``build/``, ``install/``, ``log/``). A build needs
colcon, CMake, a C/C++ compiler and the rosidl build tools: a sourced ROS 2 Jazzy, or the
``ros-jazzy-*`` interface-building wheels of ``requirements-dev.txt`` in this interpreter's venv,
whose CMake export files :mod:`cbha_inverse.interfaces.rosidl_exports` must have repaired first
(``make install`` does both).

The libraries are installed with the run path ``$ORIGIN`` (and the Python extensions with
``$ORIGIN/../../..``), so they find each other without ``LD_LIBRARY_PATH``. The ROS type support
still opens ``lib<pkg>__rosidl_typesupport_*.so`` by name, which only works when
``LD_LIBRARY_PATH`` names ``install/<package>/lib`` at process start: source
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

SHIPPED = Path(__file__).resolve().parent
"""The folder of the shipped ament_cmake packages (``<package>/package.xml``, ``msg/``)."""

BUILD_TOOLS = ('ament_cmake', 'rosidl_default_generators')
"""What ``find_package`` must find (under ``share/<name>/cmake``) for any build to configure."""


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


def check_build_tools(env, dependencies=('builtin_interfaces',)):
    """
    Raise :class:`BuildError` naming the first missing build tool.

    Parameters
    ----------
    env : mapping
        The build environment (:func:`build_environment`).
    dependencies : sequence of str
        The interface packages the package depends on (found like the build tools).

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
    for name in (*BUILD_TOOLS, *dependencies):
        if not any((Path(p) / 'share' / name / 'cmake').is_dir() for p in prefixes):
            raise BuildError(f'CMake package {name} not found under {prefixes}: install the '
                             'interface-building pins of requirements-dev.txt (make install), '
                             'or source a ROS 2 Jazzy install')
    return colcon


def install_prefix(workspace, package):
    """Return the install prefix of a package in a workspace (``install/<package>``)."""
    return Path(workspace) / 'install' / package


def interface_environment(prefix, base=None):
    """
    Return the environment in which a process can import and use the built messages.

    Parameters
    ----------
    prefix : str or os.PathLike or None
        The package's install prefix (:func:`install_prefix`); None: the package is installed
        where every process finds it (the venv, ``make install``; a sourced ROS 2 install).
    base : mapping, optional
        Starting environment (default ``os.environ``).

    Returns
    -------
    dict
        ``base`` with ``PYTHONPATH``, ``LD_LIBRARY_PATH``, ``AMENT_PREFIX_PATH`` and
        ``CMAKE_PREFIX_PATH`` prepended as ``install/setup.sh`` would (a Python child that imports
        rclpy must start with it: the library path is read at process start); ``base`` as it is
        for a prefix None.

    """
    if prefix is None:
        return dict(os.environ if base is None else base)
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


def build_interface_package(package, workspace, dependencies, timeout=600.0, env=None):
    """
    Copy a shipped package into ``<workspace>/src`` and build it with colcon.

    Parameters
    ----------
    package : str
        The shipped package (a folder of :data:`SHIPPED`).
    workspace : str or os.PathLike
        Workspace folder (created if missing; an earlier build there is reused by colcon).
    dependencies : sequence of str
        The interface packages it depends on (checked before the build).
    timeout : float  [s]
        Longest build.
    env : mapping, optional
        Starting environment (default ``os.environ``).

    Returns
    -------
    pathlib.Path
        The install prefix (``<workspace>/install/<package>``).

    Raises
    ------
    BuildError
        If a build tool is missing, the export files are not repaired, or colcon fails (the
        message ends with the tail of the colcon output).

    """
    build_interface_packages({package: dependencies}, workspace, timeout, env)
    return install_prefix(workspace, package)


def build_interface_packages(packages, workspace, timeout=600.0, env=None):
    """
    Build several shipped packages in one colcon run (in parallel, as colcon schedules them).

    Parameters
    ----------
    packages : mapping of str to sequence of str
        The shipped packages and the interface packages each depends on.
    workspace : str or os.PathLike
        Workspace folder (created if missing; an earlier build there is reused by colcon).
    timeout : float  [s]
        Longest build.
    env : mapping, optional
        Starting environment (default ``os.environ``).

    Returns
    -------
    pathlib.Path
        The workspace (each package installed in ``install/<package>``, built in
        ``build/<package>``).

    Raises
    ------
    BuildError
        As :func:`build_interface_package`.

    """
    workspace = Path(workspace).resolve()
    build_env = build_environment(env)
    colcon = check_build_tools(
        build_env, tuple(dict.fromkeys(d for deps in packages.values() for d in deps)))
    broken = [path for prefix in _prefixes(build_env) for path in broken_exports(prefix)]
    if broken:
        raise BuildError(f'{len(broken)} CMake export files name include folders missing here '
                         f'(e.g. {broken[0]}): run python -m cbha_inverse.interfaces.'
                         'rosidl_exports (make install does)')
    for package in packages:
        source = workspace / 'src' / package
        if source.exists():
            shutil.rmtree(source)
        shutil.copytree(SHIPPED / package, source)
    names = ', '.join(packages)
    command = [colcon, '--log-base', str(workspace / 'log'), 'build',
               '--base-paths', str(workspace / 'src'), '--packages-select', *packages,
               '--build-base', str(workspace / 'build'),
               '--install-base', str(workspace / 'install'),
               '--cmake-args', f'-DPython3_EXECUTABLE={sys.executable}', '-DBUILD_TESTING=OFF',
               '-DCMAKE_INSTALL_RPATH=$ORIGIN;$ORIGIN/../../..']
    try:
        result = subprocess.run(command, cwd=workspace, env=build_env, capture_output=True,
                                text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        raise BuildError(f'colcon build of {names} took more than {timeout:g} s') from None
    if result.returncode != 0:
        tail = '\n'.join((result.stdout + result.stderr).strip().splitlines()[-25:])
        raise BuildError(f'colcon build of {names} failed (exit {result.returncode}); '
                         f'log in {workspace / "log"}:\n{tail}')
    return workspace


def build_command(package, dependencies, description, use, argv=None):
    """
    Run the command line of a package build: ``--workspace WS`` (default ``<package>_ws``).

    Parameters
    ----------
    package : str
        The shipped package.
    dependencies : sequence of str
        Its interface dependencies (:func:`build_interface_package`).
    description : str
        The command's ``--help`` description.
    use : str
        What the built package is for (``before starting ...``), in the success line.
    argv : list of str, optional
        Command-line arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        0 on success, 2 when the package cannot be built here (one line says why).

    """
    prog = f'cbha_build_{package}'
    parser = argparse.ArgumentParser(prog=prog, description=description)
    parser.add_argument('--workspace', default=f'{package}_ws',
                        help='workspace folder (default: %(default)s)')
    args = parser.parse_args(argv)
    try:
        prefix = build_interface_package(package, args.workspace, dependencies)
    except BuildError as exc:
        print(f'{prog}: {exc}', file=sys.stderr)
        return 2
    setup = Path(args.workspace).resolve() / 'install' / 'setup.sh'
    print(f'built {package} into {prefix}; {use}: . {setup}')
    return 0
