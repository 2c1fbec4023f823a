"""
Install the shipped interface packages into the venv, where the PyPI ROS wheels live.

``make install`` runs ``python -m cbha_inverse.interfaces.venv_install`` with the venv's
interpreter. The packages of :data:`PACKAGES` (``tf2_msgs``, ``robotino_msgs``,
``control_msgs``: the messages the nodes use that PyPI lacks) are built in one colcon run
(:func:`cbha_inverse.interfaces.colcon_build.build_interface_packages`) in the workspace
``<venv>/cbha_interfaces_ws``, then each is installed with ``cmake --install --prefix <venv>``:
the libraries into ``<venv>/lib`` beside the wheels' own, the Python packages into the venv's
``site-packages``, ``share/`` and the ament index beside the wheels'. Nothing needs sourcing:
the ROS wheels' start-up (``ros_wheels_bootstrapper``) puts ``<venv>/lib`` on
``LD_LIBRARY_PATH`` before any ROS library loads, in every Python process of the venv (a node,
a console script, a test), and the ROS type support finds ``lib<pkg>__rosidl_typesupport_*.so``
there by name. A sourced ROS 2 install still comes first: its ``PYTHONPATH`` precedes the
venv's ``site-packages``. The build itself ignores a sourced install (:data:`SOURCED`): what goes
into the venv is built against the venv's wheels.

A last step imports each package in a new process and serialises one of its messages (which
loads its type support): an install that cannot be used fails here, not in a node.
"""

import argparse
import importlib.metadata
import os
from pathlib import Path
import shutil
import subprocess
import sys

from cbha_inverse.errors import report_config_error
from cbha_inverse.interfaces.colcon_build import (
    build_environment, build_interface_packages, BuildError)

PACKAGES = {
    'tf2_msgs': ('geometry_msgs',),
    'robotino_msgs': ('builtin_interfaces',),
    'control_msgs': ('action_msgs', 'builtin_interfaces', 'std_msgs', 'trajectory_msgs'),
}
"""The shipped packages installed into the venv, and the interface packages each depends on."""

PROBES = {
    'tf2_msgs': 'from tf2_msgs.msg import TFMessage as T',
    'robotino_msgs': 'from robotino_msgs.msg import BHAReadings as T',
    'control_msgs': 'from control_msgs.action import FollowJointTrajectory as A; T = A.Goal',
}
"""One message of each package (``T``): importing and serialising it loads its type support."""

WORKSPACE = 'cbha_interfaces_ws'
"""The colcon workspace of the builds, under the prefix.

Kept: a rebuild with the same ROS wheels is incremental; other wheels start it anew."""

SOURCED = ('AMENT_PREFIX_PATH', 'CMAKE_PREFIX_PATH', 'PYTHONPATH')
"""The variables of a sourced ROS 2 install that the build and the check run without."""


def venv_environment():
    """Return ``os.environ`` without :data:`SOURCED`: the venv's packages alone."""
    return {key: value for key, value in os.environ.items() if key not in SOURCED}


def installed_ros_wheels():
    """
    Return what a build in the workspace was made with: the interpreter and the ROS wheels.

    Returns
    -------
    str
        ``sys.version`` and the ``ros-*`` distributions of the venv with their versions, one a
        line; a build made with other wheels is not reused (its CMake caches name them).

    """
    wheels = sorted(f'{d.metadata["Name"]}=={d.version}'
                    for d in importlib.metadata.distributions()
                    if (d.metadata['Name'] or '').lower().startswith('ros-'))
    return '\n'.join([sys.version, *wheels])


def probe_script(packages):
    """Return the Python source that imports and serialises one message of each package."""
    lines = ['from rclpy.serialization import serialize_message']
    for package in packages:
        lines += [PROBES[package], 'serialize_message(T())']
    return '\n'.join(lines)


def check_usable(packages, timeout=120.0):
    """
    Raise :class:`BuildError` unless a new process of this interpreter can use the packages.

    Parameters
    ----------
    packages : sequence of str
        Package names (keys of :data:`PROBES`).
    timeout : float  [s]
        Longest check.

    """
    result = subprocess.run([sys.executable, '-c', probe_script(packages)],
                            env=venv_environment(), capture_output=True, text=True,
                            timeout=timeout)
    if result.returncode != 0:
        last = (result.stderr.strip().splitlines() or ['(no output)'])[-1]
        raise BuildError(f'the installed messages are not usable in a new process: {last}')


def install_interfaces(packages=None, prefix=None, timeout=600.0):
    """
    Build the shipped interface packages and install them into a venv.

    Parameters
    ----------
    packages : sequence of str, optional
        Keys of :data:`PACKAGES` (default: all).
    prefix : str or os.PathLike, optional
        The venv (default ``sys.prefix``: this interpreter's, which builds them).
    timeout : float  [s]
        Longest build (and longest install of one package).

    Returns
    -------
    list of str
        The packages installed.

    Raises
    ------
    BuildError
        If the prefix is not this interpreter's venv, a build tool is missing, a build fails
        or the result is not usable (one message says why).

    """
    packages = list(PACKAGES if packages is None else packages)
    prefix = Path(sys.prefix if prefix is None else prefix).resolve()
    if prefix != Path(sys.prefix).resolve() or sys.prefix == sys.base_prefix:
        raise BuildError(f'{prefix}: not the venv of this interpreter ({sys.executable}); run '
                         "this command with the venv's python")
    made_with = prefix / WORKSPACE / 'made_with.txt'
    if made_with.is_file() and made_with.read_text() != installed_ros_wheels():
        shutil.rmtree(prefix / WORKSPACE)
    # colcon never crawls the workspace (a `colcon build` of a tree that holds the venv)
    (prefix / WORKSPACE).mkdir(exist_ok=True)
    (prefix / WORKSPACE / 'COLCON_IGNORE').touch()
    made_with.write_text(installed_ros_wheels())
    workspace = build_interface_packages({p: PACKAGES[p] for p in packages},
                                         prefix / WORKSPACE, timeout, venv_environment())
    env = build_environment(venv_environment())
    for package in packages:
        command = ['cmake', '--install', str(workspace / 'build' / package),
                   '--prefix', str(prefix)]
        result = subprocess.run(command, env=env, capture_output=True, text=True,
                                timeout=timeout)
        if result.returncode != 0:
            last = (result.stderr.strip().splitlines() or ['(no output)'])[-1]
            raise BuildError(f'cmake --install of {package} into {prefix} failed: {last}')
    check_usable(packages)
    return packages


def main(argv=None):
    """
    Install the shipped interface packages into this interpreter's venv; print one line.

    Parameters
    ----------
    argv : list of str, optional
        Command-line arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        0 on success, 2 when they cannot be built or installed here (one line says why).

    """
    parser = argparse.ArgumentParser(
        prog='python -m cbha_inverse.interfaces.venv_install',
        description='Build the interface packages shipped with cbha_inverse (' +
        ', '.join(PACKAGES) + ') and install them into the venv of this python.')
    parser.add_argument('packages', nargs='*', metavar='PACKAGE',
                        help='only these (default: all)')
    args = parser.parse_args(argv)
    unknown = sorted(set(args.packages) - set(PACKAGES))
    if unknown:
        parser.error(f'not a shipped package: {", ".join(unknown)} (one of {", ".join(PACKAGES)})')
    try:
        installed = install_interfaces(args.packages or None)
    except (BuildError, OSError, subprocess.TimeoutExpired) as exc:
        return report_config_error('venv_install', str(exc).splitlines()[0] if str(exc)
                                   else repr(exc))
    print(f'installed {", ".join(installed)} into {sys.prefix}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
