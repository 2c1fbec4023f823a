"""
The interface packages: installed into the venv by ``make install``, their build helpers.

``make install`` builds tf2_msgs, robotino_msgs and control_msgs into the venv
(``cbha_inverse.interfaces.venv_install``): a new process imports and serialises them with
nothing sourced, and a package first on ``PYTHONPATH`` (a sourced ROS 2 install's) still wins.
The rosidl export repair runs on export files written here in the wheels' form (a missing
builder Python and numpy include folder beside one that exists); the on-demand colcon build
(``cbha_build_robotino_msgs``) is checked for its one-line refusals.
"""

import os
from pathlib import Path
import subprocess
import sys
import sysconfig

from cbha_inverse.interfaces.colcon_build import SHIPPED
from cbha_inverse.interfaces.robotino_msgs_build import (
    build_environment, BuildError, check_build_tools, interface_environment, main, SOURCE)
from cbha_inverse.interfaces.rosidl_exports import broken_exports, repair_exports
from cbha_inverse.interfaces.venv_install import (
    install_interfaces, main as venv_install_main, PACKAGES, PROBES, SOURCED, venv_environment)
import pytest
from ros_helpers import child_env, REPO_ROOT

EXPORT = """add_library(std_msgs::std_msgs__rosidl_generator_py SHARED IMPORTED)

set_target_properties(std_msgs::std_msgs__rosidl_generator_py PROPERTIES
  INTERFACE_INCLUDE_DIRECTORIES "{folders}"
)
"""


def _write_export(prefix, package, folders):
    name = f'export_{package}__rosidl_generator_pyExport.cmake'
    path = prefix / 'share' / package / 'cmake' / name
    path.parent.mkdir(parents=True)
    path.write_text(EXPORT.format(folders=';'.join(folders)))
    return path


def test_repair_rewrites_missing_builder_includes_once_and_leaves_the_rest(tmp_path):
    python_include, numpy_include = tmp_path / 'py', tmp_path / 'np'
    python_include.mkdir()
    numpy_include.mkdir()
    existing = tmp_path / 'existing_include'
    existing.mkdir()
    builder = ['/opt/python/cp311-cp311/include/python3.11',
               '/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include']
    broken = _write_export(tmp_path / 'venv', 'std_msgs', builder + [str(existing)])
    unknown = _write_export(tmp_path / 'venv', 'odd_msgs', ['/nowhere/include'])
    fine = _write_export(tmp_path / 'venv', 'fine_msgs', [str(existing), '${_IMPORT_PREFIX}/x'])
    fine_text = fine.read_text()
    assert broken_exports(tmp_path / 'venv') == [str(broken)]

    result = repair_exports(tmp_path / 'venv', str(python_include), str(numpy_include))
    assert result.scanned == 3 and result.rewritten == (str(broken),)
    assert result.unresolved == ('/nowhere/include',)
    assert f'"{python_include};{numpy_include};{existing}"' in broken.read_text()
    assert fine.read_text() == fine_text and '/nowhere/include' in unknown.read_text()
    assert broken_exports(tmp_path / 'venv') == []

    again = repair_exports(tmp_path / 'venv', str(python_include), str(numpy_include))
    assert again.rewritten == () and again.scanned == 3


def test_this_venv_needs_no_repair_after_make_install():
    assert broken_exports(sys.prefix) == []


def test_missing_build_tool_is_one_line_and_exit_2(tmp_path, capsys, monkeypatch):
    env = build_environment({'PATH': str(tmp_path)})
    assert env['AMENT_PREFIX_PATH'].split(os.pathsep)[-1] == sys.prefix
    with pytest.raises(BuildError, match='colcon not found'):
        check_build_tools({'PATH': str(tmp_path), 'AMENT_PREFIX_PATH': str(tmp_path)})
    colcon = tmp_path / 'colcon'
    colcon.write_text('#!/bin/sh\n')
    colcon.chmod(0o755)
    with pytest.raises(BuildError, match='cmake not found'):
        check_build_tools({'PATH': str(tmp_path), 'AMENT_PREFIX_PATH': str(tmp_path)})
    real_tools = {'PATH': os.environ['PATH'] + os.pathsep + str(tmp_path),
                  'AMENT_PREFIX_PATH': str(tmp_path)}
    monkeypatch.setattr(sys, 'prefix', str(tmp_path))
    with pytest.raises(BuildError, match='CMake package ament_cmake not found'):
        check_build_tools(real_tools)
    monkeypatch.setenv('PATH', str(tmp_path))
    colcon.unlink()
    monkeypatch.setattr('sysconfig.get_paths', lambda: {'scripts': str(tmp_path)})
    assert main(['--workspace', str(tmp_path / 'ws')]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith('cbha_build_robotino_msgs: colcon not found') and '\n' not in err


def test_interface_environment_is_what_setup_sh_gives(tmp_path):
    env = interface_environment(tmp_path / 'install' / 'robotino_msgs',
                                {'LD_LIBRARY_PATH': '/a', 'PATH': '/bin'})
    prefix = (tmp_path / 'install' / 'robotino_msgs').resolve()
    version = f'python{sys.version_info.major}.{sys.version_info.minor}'
    assert env['LD_LIBRARY_PATH'] == f'{prefix / "lib"}{os.pathsep}/a'
    assert env['PYTHONPATH'] == str(prefix / 'lib' / version / 'site-packages')
    assert env['AMENT_PREFIX_PATH'] == str(prefix) and env['PATH'] == '/bin'


def test_shipped_messages_have_the_driver_fields():
    """The field lines (comments aside) are the driver's, so the type hashes match it."""
    def fields(name):
        lines = (SOURCE / 'msg' / name).read_text().splitlines()
        return [line.split('#')[0].split() for line in lines if line.split('#')[0].strip()]

    assert fields('SetBHAPressures.msg') == [['float32[]', 'pressures']]
    assert fields('BHAReadings.msg') == [['builtin_interfaces/Time', 'stamp'],
                                         ['float32[]', 'pressures'], ['float32[]', 'cablepull']]


def test_repair_command_line_on_a_prefix(tmp_path):
    _write_export(tmp_path, 'std_msgs', ['/opt/python/cp311-cp311/include/python3.11'])
    result = subprocess.run(
        [sys.executable, '-m', 'cbha_inverse.interfaces.rosidl_exports', str(tmp_path)],
        cwd=REPO_ROOT, env=child_env(), capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert '1 scanned, 1 rewritten' in result.stdout
    missing = subprocess.run(
        [sys.executable, '-m', 'cbha_inverse.interfaces.rosidl_exports', str(tmp_path / 'no')],
        cwd=REPO_ROOT, env=child_env(), capture_output=True, text=True, timeout=60)
    assert missing.returncode == 2 and missing.stderr.strip().endswith('not a folder')


def test_built_messages_have_the_fields_of_the_shipped_files(robotino_msgs):
    """The colcon build's Python types carry exactly the fields of the ``.msg`` files."""
    from robotino_helpers import messages
    set_pressures, readings = messages()
    assert set_pressures.get_fields_and_field_types() == {'pressures': 'sequence<float>'}
    assert readings.get_fields_and_field_types() == {
        'stamp': 'builtin_interfaces/Time', 'pressures': 'sequence<float>',
        'cablepull': 'sequence<float>'}


PROBE = """
import sys
from rclpy.serialization import deserialize_message, serialize_message
from control_msgs.action import FollowJointTrajectory
from robotino_msgs.msg import BHAReadings
from tf2_msgs.msg import TFMessage
goal = FollowJointTrajectory.Goal()
goal.trajectory.joint_names = ['a', 'b']
assert deserialize_message(serialize_message(goal), FollowJointTrajectory.Goal) == goal
for module in (FollowJointTrajectory, BHAReadings, TFMessage):
    print(sys.modules[module.__module__].__file__)
"""


def test_make_install_put_the_messages_into_the_venv():
    """A new process of the venv, nothing sourced, imports and serialises all three packages."""
    env = child_env()
    for key in ('AMENT_PREFIX_PATH', 'CMAKE_PREFIX_PATH'):
        env.pop(key, None)
    result = subprocess.run([sys.executable, '-c', PROBE], cwd=REPO_ROOT, env=env,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    site = Path(sysconfig.get_paths()['purelib']).resolve()
    files = [Path(line).resolve() for line in result.stdout.split()]
    assert len(files) == 3 and all(site in f.parents for f in files), result.stdout
    for package in PACKAGES:
        assert sorted(Path(sys.prefix, 'lib').glob(f'lib{package}__rosidl_typesupport_c.so'))


def test_a_package_first_on_pythonpath_wins_over_the_venvs(tmp_path):
    """A sourced ROS 2 install's packages (first on ``PYTHONPATH``) come before the venv's."""
    stand_in = tmp_path / 'tf2_msgs'
    stand_in.mkdir()
    (stand_in / '__init__.py').write_text('ORIGIN = "sourced"\n')
    env = child_env()
    env['PYTHONPATH'] = os.pathsep.join([str(tmp_path), env['PYTHONPATH']])
    result = subprocess.run([sys.executable, '-c', 'import tf2_msgs; print(tf2_msgs.ORIGIN)'],
                            cwd=REPO_ROOT, env=env, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0 and result.stdout.strip() == 'sourced', result.stderr


def test_follow_joint_trajectory_has_the_fields_of_jazzy():
    from control_msgs.action import FollowJointTrajectory
    from control_msgs.msg import JointComponentTolerance
    assert FollowJointTrajectory.Goal.get_fields_and_field_types() == {
        'trajectory': 'trajectory_msgs/JointTrajectory',
        'multi_dof_trajectory': 'trajectory_msgs/MultiDOFJointTrajectory',
        'path_tolerance': 'sequence<control_msgs/JointTolerance>',
        'component_path_tolerance': 'sequence<control_msgs/JointComponentTolerance>',
        'goal_tolerance': 'sequence<control_msgs/JointTolerance>',
        'component_goal_tolerance': 'sequence<control_msgs/JointComponentTolerance>',
        'goal_time_tolerance': 'builtin_interfaces/Duration'}
    assert FollowJointTrajectory.Result.GOAL_TOLERANCE_VIOLATED == -5
    assert list(FollowJointTrajectory.Feedback.get_fields_and_field_types()) == [
        'header', 'joint_names', 'desired', 'actual', 'error', 'multi_dof_joint_names',
        'multi_dof_desired', 'multi_dof_actual', 'multi_dof_error']
    assert JointComponentTolerance.ROTATION == 5


def test_venv_install_refuses_another_prefix_and_unknown_packages(tmp_path, capsys):
    with pytest.raises(BuildError, match='not the venv of this interpreter'):
        install_interfaces(prefix=tmp_path)
    with pytest.raises(SystemExit) as stop:
        venv_install_main(['nav2_msgs'])
    assert stop.value.code == 2
    assert 'not a shipped package: nav2_msgs' in capsys.readouterr().err
    for package in PACKAGES:
        assert package in PROBES and (SHIPPED / package / 'package.xml').is_file()


def test_the_venv_build_ignores_a_sourced_ros_2(monkeypatch):
    """What goes into the venv is built against the venv's wheels, a sourced install aside."""
    for key in SOURCED:
        monkeypatch.setenv(key, '/opt/ros/jazzy')
    env = venv_environment()
    assert not set(SOURCED) & set(env) and env['PATH'] == os.environ['PATH']
    assert build_environment(env)['CMAKE_PREFIX_PATH'] == sys.prefix
