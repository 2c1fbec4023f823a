"""
Shared test set-up: import path and DDS isolation for every test process.

Each pytest process reserves its own ``ROS_DOMAIN_ID`` (domain_coordinator) and keeps discovery on
localhost, so parallel runs on one host never cross-talk; ROS logs go to a temporary directory.
"""

import contextlib
import fcntl
import os
from pathlib import Path
import sys
import tempfile

import pytest

# One BLAS thread before numpy loads (see cbha_inverse/__init__.py): small dense solves are ~50x
# slower with OpenBLAS worker threads on a loaded 2-core machine.
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
os.environ.setdefault('OMP_NUM_THREADS', '1')

REPO_ROOT = Path(__file__).resolve().parents[1]
if str(REPO_ROOT) not in sys.path:
    sys.path.insert(0, str(REPO_ROOT))

_RESERVATION = contextlib.ExitStack()


def _isolate_dds():
    """Reserve a domain id for this process and set the ROS environment before rclpy starts."""
    from domain_coordinator import domain_id
    os.environ['ROS_DOMAIN_ID'] = str(_RESERVATION.enter_context(domain_id()))
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    os.environ['FASTDDS_BUILTIN_TRANSPORTS'] = 'UDPv4'
    os.environ['ROS_LOG_DIR'] = tempfile.mkdtemp(prefix='cbha_ros_log_')
    os.environ.pop('RMW_IMPLEMENTATION', None)


def pytest_configure(config):
    """Isolate DDS for the whole session and silence lark's deprecation noise."""
    _isolate_dds()
    config.addinivalue_line('filterwarnings', 'ignore::DeprecationWarning:lark.*')
    config.addinivalue_line('markers', 'linter: the ament linters')
    config.addinivalue_line('markers', 'flake8: ament_flake8')
    config.addinivalue_line('markers', 'pep257: ament_pep257')


# Tests whose bounds include the timing of several node processes (closed-loop tracking, lag,
# replays, hosts, start-up): under pytest-xdist they run one after the other on one worker
# (--dist loadgroup), so two of them never share the cores; the rest runs beside them.
CLOSED_LOOP_FILES = (
    'test/ros/test_ros_excite.py', 'test/ros/test_ros_lifecycle.py',
    'test/ros/test_ros_robotino_bridge.py', 'test/system/test_commands.py',
    'test/system/test_demo_bags.py', 'test/system/test_demo_proprio.py',
    'test/system/test_launch.py', 'test/system/test_network_hosts.py',
    'test/system/test_own_robot_guide.py', 'test/system/test_replay_regression.py',
    'test/system/test_ros_loop.py')


def pytest_collection_modifyitems(config, items):
    """Put the closed-loop tests into one pytest-xdist group (:data:`CLOSED_LOOP_FILES`)."""
    for item in items:
        if item.nodeid.split('::', 1)[0] in CLOSED_LOOP_FILES:
            item.add_marker(pytest.mark.xdist_group('closed_loop'))


def pytest_unconfigure(config):
    """Release the reserved domain id."""
    _RESERVATION.close()


@pytest.fixture
def rclpy_context():
    """
    Yield a private, initialised ``rclpy.Context`` without signal handlers.

    Nodes created with ``context=`` this object and executors built on it are isolated from other
    tests; the context is shut down afterwards.
    """
    import rclpy
    from rclpy.signals import SignalHandlerOptions
    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    try:
        yield context
    finally:
        rclpy.try_shutdown(context=context)


def _built_once(tmp_path_factory, package, build_and_load):
    """Return ``build_and_load(workspace)``: one build per session, shared by xdist workers."""
    if os.environ.get('PYTEST_XDIST_WORKER') is None:
        return build_and_load(tmp_path_factory.mktemp(f'{package}_ws'))
    # pytest-xdist: the workers share one build (their base temporary folders have one parent);
    # the first to take the lock builds, the others load what it built
    shared = tmp_path_factory.getbasetemp().parent
    with open(shared / f'{package}_ws.lock', 'w') as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        return build_and_load(shared / f'{package}_ws')


@pytest.fixture(scope='session')
def robotino_msgs(tmp_path_factory):
    """
    Build the shipped ``robotino_msgs`` with colcon once per session and load it.

    Returns the install prefix; ``from robotino_msgs.msg import ...`` works afterwards in this
    process, and ``robotino_helpers.robotino_child_env(prefix)`` gives child processes the
    environment of its ``install/setup.sh``.
    """
    from robotino_helpers import build_and_load
    return _built_once(tmp_path_factory, 'robotino_msgs', build_and_load)


@pytest.fixture(scope='session')
def tf2_msgs(tmp_path_factory):
    """
    Make ``tf2_msgs`` usable: the system one (a sourced ROS 2), else the shipped one, built once.

    Returns None for the system package, else the install prefix of the build (loaded in this
    process; ``interface_environment(prefix, child_env())`` for child processes).
    """
    import importlib.util
    if importlib.util.find_spec('tf2_msgs') is not None:
        return None
    from cbha_inverse.interfaces.tf2_msgs_build import build_tf2_msgs
    from ros_helpers import load_interface
    return _built_once(tmp_path_factory, 'tf2_msgs',
                       lambda workspace: load_interface(build_tf2_msgs(workspace)))
