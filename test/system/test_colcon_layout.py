"""
The colcon install layout: build with colcon, then do what ``ros2 run cbha_inverse <exe>`` does.

ros2cli is not on PyPI, so the test reproduces ``ros2 run``: find the package prefix through
``ament_index_python.get_package_prefix``, run ``<prefix>/lib/cbha_inverse/<exe>`` with
``--ros-args --params-file <prefix>/share/cbha_inverse/config/<exe>.yaml`` and check over real DDS
that the node does its job.
"""

import os
from pathlib import Path
import shutil
import subprocess
import sys
import time

import pytest
from ros_helpers import colcon_build, install_env, REPO_ROOT

PACKAGE = 'cbha_inverse'
NODE_EXECUTABLES = ('trajectory', 'inverse_solver', 'cbha_sim', 'stereo_tracker',
                    'robotino_bridge', 'cbha_excite')
COMMAND_EXECUTABLES = ('condense_segment', 'cbha_report', 'cbha_demo', 'cbha_launch',
                       'cbha_scene', 'stereo_calibrate', 'cbha_build_robotino_msgs',
                       'cbha_build_tf2_msgs', 'cbha_bag')


@pytest.fixture(scope='module')
def colcon_install(tmp_path_factory):
    """Build the package with colcon into a temporary workspace; return the install base."""
    work = tmp_path_factory.mktemp('colcon')
    yield colcon_build(work)
    shutil.rmtree(work, ignore_errors=True)


def test_install_has_ros2_run_layout(colcon_install, monkeypatch):
    """The ament index finds the package; each executable and params file is where ros2 expects."""
    from ament_index_python.packages import get_package_prefix
    from ament_index_python.packages import get_package_share_directory
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(colcon_install / PACKAGE))
    prefix = Path(get_package_prefix(PACKAGE))
    share = Path(get_package_share_directory(PACKAGE))
    assert prefix == colcon_install / PACKAGE
    for exe in NODE_EXECUTABLES + COMMAND_EXECUTABLES:
        path = prefix / 'lib' / PACKAGE / exe
        assert path.is_file() and os.access(path, os.X_OK), f'{path} missing or not executable'
    for node in NODE_EXECUTABLES:
        assert (share / 'config' / f'{node}.yaml').is_file(), f'no params file for {node}'
    assert (share / 'package.xml').read_text() == (REPO_ROOT / 'package.xml').read_text()
    assert any((share / 'meshes').iterdir()), 'meshes/ not installed'
    for installed in ('launch/sim.launch.py', 'launch/robot.launch.py', 'rviz/cbha.rviz'):
        assert (share / installed).read_text() == (REPO_ROOT / installed).read_text(), installed


def test_installed_package_finds_its_share_dir(colcon_install):
    """Installed code resolves config/ through the ament index, not through the source tree."""
    prefix = colcon_install / PACKAGE
    code = ('import cbha_inverse, cbha_inverse.paths as p; '
            'print(cbha_inverse.__file__); print(p.config_path())')
    out = subprocess.run([sys.executable, '-c', code], env=install_env(prefix), cwd=prefix,
                         capture_output=True, text=True, timeout=60, check=True).stdout.split()
    assert Path(out[0]).is_relative_to(prefix), f'imported {out[0]} instead of the install'
    assert Path(out[1]) == prefix / 'share' / PACKAGE / 'config'


def test_ros2_run_trajectory_publishes_targets(colcon_install, rclpy_context, monkeypatch):
    """The installed ``trajectory`` executable, run as ros2 run would, publishes PointStamped."""
    from ament_index_python.packages import get_package_prefix
    from geometry_msgs.msg import PointStamped
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    monkeypatch.setenv('AMENT_PREFIX_PATH', str(colcon_install / PACKAGE))
    prefix = Path(get_package_prefix(PACKAGE))
    executable = prefix / 'lib' / PACKAGE / 'trajectory'
    params = prefix / 'share' / PACKAGE / 'config' / 'trajectory.yaml'

    node = Node('layout_listener', context=rclpy_context)
    received = []
    node.create_subscription(PointStamped, '/target', received.append, 10)
    executor = SingleThreadedExecutor(context=rclpy_context)
    executor.add_node(node)
    process = subprocess.Popen(
        [str(executable), '--ros-args', '--params-file', str(params)],
        env=install_env(prefix), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 30.0
        while len(received) < 5 and time.monotonic() < deadline and process.poll() is None:
            executor.spin_once(timeout_sec=0.1)
    finally:
        process.terminate()
        output, _ = process.communicate(timeout=20)
        executor.shutdown()
        node.destroy_node()
    assert len(received) >= 5, f'received {len(received)} targets; node output:\n{output}'
    assert all(msg.header.frame_id == 'cbha_base' for msg in received)
    assert process.returncode == 0, f'exit code {process.returncode} on SIGTERM:\n{output}'


def test_installed_cbha_launch_uses_the_installed_params_files(colcon_install):
    """``cbha_launch`` of the install resolves every params file in the install's share dir."""
    prefix = colcon_install / PACKAGE
    result = subprocess.run([str(prefix / 'lib' / PACKAGE / 'cbha_launch'), 'sim', '--dry-run'],
                            env=install_env(prefix), cwd=prefix, capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert [line.split(':')[0] for line in lines] == ['trajectory', 'inverse_solver', 'cbha_sim']
    for line in lines:
        node = line.split(':')[0]
        assert f"--params-file {prefix / 'share' / PACKAGE / 'config' / node}.yaml" in line, line


def test_shipped_robotino_msgs_is_installed_as_data_and_not_crawled(colcon_install, tmp_path):
    """
    The shipped interface packages are package data, and colcon does not build them by itself.

    colcon stops descending at a package's folder, so a workspace holding cbha_inverse lists
    only cbha_inverse; a robotino_msgs of the driver's source in the same workspace cannot
    clash with the copy (which ``cbha_build_robotino_msgs`` builds on request).
    """
    site = (colcon_install / PACKAGE / 'lib' /
            f'python{sys.version_info.major}.{sys.version_info.minor}' / 'site-packages')
    for shipped, messages in ((site / PACKAGE / 'interfaces' / 'robotino_msgs',
                               ('SetBHAPressures', 'BHAReadings')),
                              (site / PACKAGE / 'interfaces' / 'tf2_msgs', ('TFMessage',))):
        for name in ('package.xml', 'CMakeLists.txt', *(f'msg/{m}.msg' for m in messages)):
            assert (shipped / name).is_file(), f'{shipped / name} not installed'
    (tmp_path / 'src').mkdir()
    (tmp_path / 'src' / PACKAGE).symlink_to(REPO_ROOT, target_is_directory=True)
    colcon = Path(sys.executable).with_name('colcon')
    listed = subprocess.run([str(colcon), '--log-base', str(tmp_path / 'log'), 'list',
                             '--names-only',
                             '--base-paths', str(tmp_path / 'src')], cwd=tmp_path,
                            capture_output=True, text=True, timeout=120, check=True).stdout
    assert listed.split() == [PACKAGE]
