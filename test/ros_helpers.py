"""
Helpers for the node tests over real DDS: nodes, messages, bounded spinning, child processes.

rclpy and the message packages are imported inside the functions, so that importing this module
costs nothing for the tests that do not use them.
"""

import contextlib
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]


def make_node(node_class, context, namespace='/cbha', **params):
    """
    Create a node of ``node_class`` in ``context`` with ``params`` as parameter overrides.

    Parameters
    ----------
    node_class : type
        An ``rclpy.node.Node`` subclass taking ``context``, ``namespace`` and
        ``parameter_overrides`` (every node of the package does).
    context : rclpy.Context
        The test's context (the ``rclpy_context`` fixture).
    namespace : str
        Node namespace.
    **params
        Parameter name -> value.

    Returns
    -------
    rclpy.node.Node
        The node.

    """
    from rclpy.parameter import Parameter
    return node_class(context=context, namespace=namespace, parameter_overrides=[
        Parameter(name, value=value) for name, value in params.items()])


def set_parameters(node, **values):
    """
    Set parameters of a node as one change, through rclpy's parameter API in the process.

    The same callbacks run as for a ``set_parameters`` service request. A dotted name is written
    with ``__`` (``marker__min_area`` for ``marker.min_area``).

    Returns
    -------
    rcl_interfaces.msg.SetParametersResult
        ``successful`` and the ``reason`` of a refusal.

    """
    from rclpy.parameter import Parameter
    return node.set_parameters_atomically([
        Parameter(name.replace('__', '.'), value=value) for name, value in values.items()])


def assert_refused(node, reason, **values):
    """Assert that a change is refused, ``reason`` in its answer, and every value stays."""
    names = [name.replace('__', '.') for name in values]
    before = [node.get_parameter(name).value for name in names]
    result = set_parameters(node, **values)
    assert not result.successful and reason in result.reason, result
    assert [node.get_parameter(name).value for name in names] == before, names


def target_point(point, frame_id='cbha_base'):
    """Return a ``PointStamped`` at ``point`` (3,) [m] in ``frame_id``, stamp 0."""
    from geometry_msgs.msg import PointStamped
    message = PointStamped()
    message.header.frame_id = frame_id
    message.point.x, message.point.y, message.point.z = (float(v) for v in point)
    return message


def stamp_seconds(message):
    """Return the ``header.stamp`` of a stamped message in seconds."""
    return message.header.stamp.sec + 1e-9 * message.header.stamp.nanosec


def sim_plant_scene(scene):
    """Return the scene as ``cbha_sim`` builds its plant by default (stiffness error, gravity)."""
    from cbha_inverse.ros.nodes.cbha_sim import CbhaSimParams
    from cbha_inverse.scene import load_scene
    return load_scene(scene, stiffness_scale=CbhaSimParams.stiffness_scale,
                      gravity=CbhaSimParams.gravity)


def loop_lag_error(rate_hz):
    """
    Return the tracking error [m] that the closed loop's lag alone gives on the default path.

    No feedback of the inverse solver's structure removes the loop lag: ``cbha_sim``'s valve time
    constant and transport latency (its defaults) plus one plant tick and one control tick at
    ``rate_hz``. At the trajectory's default speed (the paper's circle, 2.5 cm/s) the target
    runs ``speed * lag`` ahead of the tip (1.3 mm at 50 Hz).

    Parameters
    ----------
    rate_hz : float  [Hz]
        Rate of the plant and of the solver.

    Returns
    -------
    float  [m]
        ``speed * lag``.

    """
    from cbha_inverse.ros.nodes.cbha_sim import CbhaSimParams
    from cbha_inverse.ros.nodes.trajectory import TrajectoryParams
    lag = CbhaSimParams.valve_time_constant + CbhaSimParams.latency + 2.0 / rate_hz
    return TrajectoryParams.speed * lag


def record_tracking(context, nodes, duration, hold, settle, rate_hz):
    """
    Spin ``nodes`` of a closed loop in ``/cbha``; return its tip errors against the targets.

    A recorder takes ``target`` and ``tip/true``; once the first target arrives the loop runs
    ``duration`` seconds, and the errors are scored from ``hold + settle`` seconds after the first
    target to the last one (:func:`cbha_inverse.metrics.tracking_errors`). The loop's threads run
    at real-time priority where the OS allows it (:func:`real_time_priority`).

    Parameters
    ----------
    context : rclpy.Context
        The test's context.
    nodes : list of rclpy.node.Node
        The loop (a trajectory, a solver, a plant, ...); destroyed afterwards.
    duration, hold, settle : float  [s]
        Run time after the first target, the trajectory's ``start_hold``, the settling time.
    rate_hz : float  [Hz]
        Rate of the plant: at least half of its tips in the scored window must arrive.

    Returns
    -------
    TrackingErrors
        ``rms``, ``maximum`` and the ``errors`` [m].

    """
    if os.environ.get('CBHA_TEST_TIMING') != '1':
        pytest.fail('a closed loop in a test outside the timing phase: add its file to '
                    'TIMING_FILES in test/conftest.py or mark the test @pytest.mark.timing')
    from cbha_inverse.metrics import tracking_errors
    from cbha_inverse.ros.common.qos import MEASURED_QOS, TARGET_QOS
    from geometry_msgs.msg import PointStamped
    from rclpy.node import Node
    recorder = Node('recorder', context=context, namespace='/cbha')
    targets, tips = [], []

    def stamped(message):
        return (stamp_seconds(message), message.point.x, message.point.y, message.point.z)

    recorder.create_subscription(PointStamped, 'target', lambda m: targets.append(stamped(m)),
                                 TARGET_QOS)
    recorder.create_subscription(PointStamped, 'tip/true', lambda m: tips.append(stamped(m)),
                                 MEASURED_QOS)
    with spinning(context, *nodes, recorder) as executor, real_time_priority():
        assert spin_until(executor, lambda: len(targets) > 0, 10.0)
        spin_for(executor, duration)
    errors = tracking_errors([t[0] for t in targets], [t[1:] for t in targets],
                             [t[0] for t in tips], [t[1:] for t in tips],
                             targets[0][0] + hold + settle, targets[-1][0])
    assert errors.errors.size > 0.5 * rate_hz * (duration - hold - settle), 'too few tip samples'
    return errors


REAL_TIME_PRIORITY = 10
"""SCHED_RR priority of a closed loop's threads: above the time-shared processes, low in 1-99."""


@contextlib.contextmanager
def real_time_priority():
    """
    Run every thread of this process (executor, DDS receive threads) at SCHED_RR, then restore.

    A closed loop spun in the test process (:func:`record_tracking`) is bounded by its own
    timing: on cores shared with other jobs (another suite, a compile) one stalled for 0.5 s, a
    2 mm error in a loop held to 1.3 mm. At :data:`REAL_TIME_PRIORITY` time-shared processes no
    longer preempt it; the loop itself (its nodes in this one executor, the same ticks) is
    unchanged. Where the OS refuses (no ``CAP_SYS_NICE``), the threads keep their policy.
    """
    previous = {}
    for task in Path('/proc/self/task').iterdir():
        with contextlib.suppress(OSError, ValueError):
            tid = int(task.name)
            policy, param = os.sched_getscheduler(tid), os.sched_getparam(tid)
            os.sched_setscheduler(tid, os.SCHED_RR, os.sched_param(REAL_TIME_PRIORITY))
            previous[tid] = policy, param
    try:
        yield
    finally:
        for tid, (policy, param) in previous.items():
            with contextlib.suppress(OSError):
                os.sched_setscheduler(tid, policy, param)


def real_time_child():
    """
    Switch a child process to SCHED_RR :data:`REAL_TIME_PRIORITY` where allowed (a preexec_fn).

    Its threads (the DDS receive threads too) inherit the policy: a process that must keep up
    with a stream (a bag recorder) is then not starved by the other jobs on the shared cores.
    """
    with contextlib.suppress(OSError):
        os.sched_setscheduler(0, os.SCHED_RR, os.sched_param(REAL_TIME_PRIORITY))


def spin_until(executor, predicate, timeout):
    """
    Spin ``executor`` until ``predicate()`` is true or ``timeout`` seconds passed.

    Returns
    -------
    bool
        Whether the predicate became true.

    """
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        executor.spin_once(timeout_sec=0.02)
    return bool(predicate())


@contextlib.contextmanager
def spinning(context, *nodes):
    """Yield one executor over ``nodes``; shut it down and destroy the nodes afterwards."""
    from rclpy.executors import SingleThreadedExecutor
    executor = SingleThreadedExecutor(context=context)
    for node in nodes:
        executor.add_node(node)
    try:
        yield executor
    finally:
        executor.shutdown()
        for node in nodes:
            node.destroy_node()


def loop_listener(context, namespace='/cbha'):
    """
    Return a node that keeps every ``pressure_command`` and ``tip/measured`` it receives.

    Returns
    -------
    executor : rclpy.executors.SingleThreadedExecutor
        Spinning the listener (shut it down and destroy the node afterwards).
    listener : rclpy.node.Node
    commands, tips : list
        The received messages.

    """
    from cbha_inverse.ros.common.qos import COMMAND_QOS, MEASURED_QOS
    from geometry_msgs.msg import PointStamped
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from std_msgs.msg import Float64MultiArray
    listener = Node('loop_listener', context=context, namespace=namespace)
    commands, tips = [], []
    listener.create_subscription(Float64MultiArray, 'pressure_command', commands.append,
                                 COMMAND_QOS)
    listener.create_subscription(PointStamped, 'tip/measured', tips.append, MEASURED_QOS)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(listener)
    return executor, listener, commands, tips


def spin_for(executor, duration):
    """Spin ``executor`` for ``duration`` seconds."""
    deadline = time.monotonic() + duration
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.01)


BOOTSTRAP_FLAG = '_ROS_WHEELS_BOOTSTRAP_COMPLETE'
"""Set by the ROS wheels' start-up hook once it re-executed Python with their library path."""


def keep_wheels_bootstrap(env):
    """
    Return ``env`` with the wheels' bootstrap flag kept only if it already has their library path.

    Every Python of the venv starts with ``ros_wheels_bootstrapper`` (a ``.pth`` hook): without
    :data:`BOOTSTRAP_FLAG` it adds the venv's ``lib`` and the wheels' ``ros_*.libs`` folders to
    ``LD_LIBRARY_PATH`` and re-executes the interpreter (a second start: ~0.1 s, more when
    coverage starts in both). A child whose ``LD_LIBRARY_PATH`` already names every one of those
    folders (this bootstrapped process's own, inherited) needs no second start and keeps the
    flag; any other environment loses it and bootstraps itself.

    Parameters
    ----------
    env : dict
        A child's environment (changed in place).

    Returns
    -------
    dict
        ``env``.

    """
    try:
        from ros_wheels_bootstrapper import get_ros_paths
    except ImportError:
        env.pop(BOOTSTRAP_FLAG, None)
        return env
    needed = {path for path in get_ros_paths().split(os.pathsep) if path}
    present = set(env.get('LD_LIBRARY_PATH', '').split(os.pathsep))
    if env.get(BOOTSTRAP_FLAG) != '1' or not needed <= present:
        env.pop(BOOTSTRAP_FLAG, None)
    return env


def child_env():
    """
    Return an environment for a Python child process that imports rclpy.

    The rclpy wheels re-exec Python once with their LD_LIBRARY_PATH; a child that inherits the
    bootstrap flag without that path cannot import rclpy, so the flag is kept only when the
    environment already has that path (:func:`keep_wheels_bootstrap`: the child then starts once,
    not twice), else dropped (the child bootstraps itself). The DDS isolation variables of
    test/conftest.py are inherited. A child
    stopped by SIGABRT (or another fatal signal) prints the stack of every thread
    (``PYTHONFAULTHANDLER``): what a test that finds a child hung sends it (:func:`stack_dump`).
    """
    env = keep_wheels_bootstrap(dict(os.environ))
    env['PYTHONPATH'] = os.pathsep.join(p for p in [str(REPO_ROOT), env.get('PYTHONPATH')] if p)
    env['PYTHONUNBUFFERED'] = '1'
    env['PYTHONFAULTHANDLER'] = '1'
    return env


def hiding_env(folder, *packages, base=None):
    """
    Return a :func:`child_env` in which importing the given packages fails.

    ``make install`` puts tf2_msgs, robotino_msgs and control_msgs into the venv; a test of a
    node without one of them prepends to ``PYTHONPATH`` a folder whose ``<package>/__init__.py``
    raises ImportError (as a sourced ROS 2 install's packages come first, this one does).

    Parameters
    ----------
    folder : pathlib.Path
        An empty folder for the stand-in packages.
    *packages : str
        Names of the packages to hide.
    base : mapping, optional
        The environment to extend (default :func:`child_env`).

    """
    for package in packages:
        (folder / package).mkdir(parents=True, exist_ok=True)
        (folder / package / '__init__.py').write_text(
            f'raise ImportError("No module named {package!r} (hidden by the test)")\n')
    env = dict(child_env() if base is None else base)
    env['PYTHONPATH'] = os.pathsep.join(p for p in [str(folder), env.get('PYTHONPATH')] if p)
    return env


def stack_dump(process, timeout=10.0):
    """
    Stop a hung child with SIGABRT and return its remaining output: its threads' stacks.

    Parameters
    ----------
    process : subprocess.Popen
        A child started with :func:`child_env` (text output with stderr merged).
    timeout : float  [s]
        How long to wait for it after the signal (then it is killed).

    Returns
    -------
    str

    """
    process.send_signal(signal.SIGABRT)
    try:
        output, _ = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        output, _ = process.communicate()
    return output or ''


def load_interface(prefix):
    """
    Make a built interface package usable in this already running process; return ``prefix``.

    A process reads ``LD_LIBRARY_PATH`` once at start, and the ROS type support opens
    ``lib<pkg>__rosidl_typesupport_*.so`` by that name; so the built libraries are loaded here by
    their full paths first (the dynamic loader then resolves the name to the loaded library), and
    the Python package's folder goes on ``sys.path``. Child processes get the environment of
    ``install/setup.sh`` instead
    (:func:`cbha_inverse.interfaces.colcon_build.interface_environment`).

    Parameters
    ----------
    prefix : pathlib.Path
        The package's install prefix (``<workspace>/install/<package>``).

    """
    import ctypes
    for library in sorted((prefix / 'lib').glob('*.so')):
        ctypes.CDLL(str(library), mode=os.RTLD_GLOBAL)
    version = f'python{sys.version_info.major}.{sys.version_info.minor}'
    site = str(prefix / 'lib' / version / 'site-packages')
    if site not in sys.path:
        sys.path.insert(0, site)
    return prefix


def colcon_build(work):
    """
    Build the package with colcon into the folder ``work``; return the install base.

    Returns
    -------
    pathlib.Path
        ``work / 'install'`` (the package prefix is ``<install base>/cbha_inverse``).

    """
    colcon = Path(sys.executable).with_name('colcon')
    assert colcon.exists(), 'colcon is not installed in this environment (requirements-dev.txt)'
    result = subprocess.run(
        [str(colcon), '--log-base', str(work / 'log'), 'build', '--paths', str(REPO_ROOT),
         '--build-base', str(work / 'build'), '--install-base', str(work / 'install')],
        cwd=work, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, f'colcon build failed:\n{result.stdout}\n{result.stderr}'
    return work / 'install'


def install_env(prefix):
    """
    Return the environment ``install/setup.sh`` gives, for a child of the installed package.

    The package's site-packages and ``prefix`` go first on ``PYTHONPATH`` and
    ``AMENT_PREFIX_PATH``; the wheels' bootstrap flag is kept or dropped as in :func:`child_env`.
    """
    env = keep_wheels_bootstrap(dict(os.environ))
    site = prefix / 'lib' / f'python{sys.version_info.major}.{sys.version_info.minor}'
    env['PYTHONPATH'] = os.pathsep.join([str(site / 'site-packages'), env.get('PYTHONPATH', '')])
    env['AMENT_PREFIX_PATH'] = os.pathsep.join([str(prefix), env.get('AMENT_PREFIX_PATH', '')])
    env['PYTHONUNBUFFERED'] = '1'
    return env


def start_node(module, *ros_args):
    """
    Start ``python -m <module> --ros-args <ros_args>`` as a child process.

    Returns
    -------
    subprocess.Popen
        The process (text stdout with stderr merged).

    """
    return subprocess.Popen(
        [sys.executable, '-m', module, '--ros-args', *ros_args], cwd=REPO_ROOT, env=child_env(),
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def interrupt(process, timeout=30.0):
    """
    Send SIGINT (Ctrl-C) to a child process and wait for it to exit.

    Returns
    -------
    tuple
        ``process.communicate()``: its remaining output (stdout, stderr).

    Raises
    ------
    subprocess.TimeoutExpired
        When it still runs after ``timeout`` seconds (:func:`reaped` kills it).

    """
    process.send_signal(signal.SIGINT)
    return process.communicate(timeout=timeout)


@contextlib.contextmanager
def reaped(*processes):
    """Kill and reap every one of ``processes`` still running when the block ends."""
    try:
        yield processes
    finally:
        for process in processes:
            if process.poll() is None:
                process.kill()
                process.communicate()


def wait_for_line(process, text, timeout):
    """Read the merged output until a line contains ``text``; return all lines read."""
    lines = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = process.stdout.readline()
        if not line:
            break
        lines.append(line)
        if text in line:
            return True, lines
    return False, lines


def aborted_logs(folder, lines=60):
    """
    Return the end of every process log under ``folder`` that holds a faulthandler stack.

    ``cbha_demo``'s processes run with ``PYTHONFAULTHANDLER``: the log of one that ended by a
    fatal signal (SIGABRT, SIGSEGV) ends with the stack of every thread. One that did not stop
    after SIGINT is named on the demo's stderr (``still running 15 s after SIGINT``).

    Parameters
    ----------
    folder : pathlib.Path
        A ``cbha_demo --output`` folder (its runs write ``<run>/<process>.log``).
    lines : int
        Lines per log.

    Returns
    -------
    str
        One block per such log (empty when there is none): an assertion message.

    """
    blocks = []
    for log in sorted(Path(folder).rglob('*.log')):
        text = log.read_text(errors='replace')
        if 'Fatal Python error' in text:
            blocks.append(f'--- {log} ---\n' + '\n'.join(text.splitlines()[-lines:]))
    return '\n'.join(blocks)
