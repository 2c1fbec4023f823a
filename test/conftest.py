"""
Shared test set-up: import path and DDS isolation for every test process.

Each pytest process reserves its own ``ROS_DOMAIN_ID`` (domain_coordinator) and keeps discovery on
localhost (participants announced every 0.2 s: ``test/data/fastdds_discovery.xml``), so parallel
runs on one host never cross-talk; ROS logs go to a temporary directory.
"""

import contextlib
import fcntl
import hashlib
import os
from pathlib import Path
import re
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
    # participants announce themselves every 0.2 s instead of 3 s: one that missed the initial
    # exchange waits that long for its peers (test/data/fastdds_discovery.xml)
    os.environ.setdefault('FASTRTPS_DEFAULT_PROFILES_FILE',
                          str(REPO_ROOT / 'test' / 'data' / 'fastdds_discovery.xml'))
    os.environ['ROS_LOG_DIR'] = tempfile.mkdtemp(prefix='cbha_ros_log_')
    os.environ.pop('RMW_IMPLEMENTATION', None)


def pytest_configure(config):
    """Isolate DDS for the whole session and silence lark's deprecation noise."""
    _isolate_dds()
    config.addinivalue_line('filterwarnings', 'ignore::DeprecationWarning:lark.*')
    config.addinivalue_line('markers', 'linter: the ament linters')
    config.addinivalue_line('markers', 'flake8: ament_flake8')
    config.addinivalue_line('markers', 'pep257: ament_pep257')
    config.addinivalue_line(
        'markers', 'timing: bounds on the timing of node processes (make test runs them alone)')
    config.addinivalue_line(
        'markers', 'untimed: a test of a timing file that bounds no timing (the first phase)')


# The timing phase of ``make test`` (``-m timing``, one process, after the rest ran on every
# core): the tests whose bounds include the timing of several node processes or of a closed loop
# (tracking RMS, lag, stop deadlines, replays, hosts, start-up). A test is in it when
# - its file is one of TIMING_FILES, or it is marked ``@pytest.mark.timing``;
# - it is an end-to-end run: a file in test/system/ not in UNTIMED_SYSTEM_FILES (so a new system
#   test is isolated without being listed);
# - its module runs an in-process closed loop through the helpers of test/ros_helpers.py
#   (CLOSED_LOOP_CALLS in its source); ``record_tracking`` also fails in a test that is not a
#   timing test, so a loop reached some other way fails loudly instead of flaking;
# and it is not marked ``@pytest.mark.untimed``: a test of such a file that bounds no timing (a
# refused parameter, a dry run, a comparison of arrays) runs in the first phase, on the workers.
TIMING_FILES = (
    'test/ros/test_ros_excite.py', 'test/ros/test_ros_fault_relay.py',
    'test/ros/test_ros_lifecycle.py', 'test/ros/test_ros_robotino_bridge.py',
    'test/ros/test_ros_trajectory_timing.py')
UNTIMED_SYSTEM_FILES = (
    'test/system/test_colcon_layout.py', 'test/system/test_docs_commands.py',
    'test/system/test_help_runs_no_work.py',
    'test/system/test_identify_check.py', 'test/system/test_installed_executables.py',
    'test/system/test_warmup.py')
CLOSED_LOOP_CALLS = re.compile(r'\b(record_tracking|loop_lag_error)\(')
_SOURCES = {}
# pytest's cache key of the seconds each test file took in the last run that ran it
DURATIONS_KEY = 'cbha_inverse/file_seconds'
# the seconds of the longest files of the first phase in one run (2 workers, load 8-11): their
# order on a clone whose pytest cache holds no durations yet (CI), where the file order alone
# starts them late on their worker
TYPICAL_FILE_SECONDS = {
    'test/identify/test_identify.py': 380.0, 'test/lint/test_flake8.py': 126.0,
    'test/system/test_installed_executables.py': 98.0, 'test/ros/test_ros_bag_play.py': 86.0,
    'test/scene/test_config_errors.py': 70.0, 'test/core/test_core_system.py': 65.0,
    'test/identify/test_identify_pots.py': 60.0, 'test/vision/test_vision_calibration.py': 48.0,
    'test/vision/test_vision_tracking.py': 47.0, 'test/system/test_warmup.py': 75.0}
_FILE_SECONDS = {}


def is_timing(item):
    """Return whether ``item`` belongs to the timing phase (see :data:`TIMING_FILES`)."""
    path = item.nodeid.split('::', 1)[0]
    if item.get_closest_marker('untimed') is not None:
        return False
    if path in TIMING_FILES or item.get_closest_marker('timing') is not None:
        return True
    if path.startswith('test/system/') and path not in UNTIMED_SYSTEM_FILES:
        return True
    if path not in _SOURCES:
        _SOURCES[path] = bool(CLOSED_LOOP_CALLS.search(Path(item.fspath).read_text()))
    return _SOURCES[path]


# ``make test``'s first phase collects every test: with CBHA_TIMING_FILES_OUT naming a file, it
# writes there the number of timing tests, then the files that hold them, one a line; the second
# phase collects those files alone (not the ~1,000 tests of the rest: 4-5 s of imports) and, with
# CBHA_TIMING_FILES_IN naming the same file, fails unless it finds as many timing tests.
TIMING_FILES_OUT = 'CBHA_TIMING_FILES_OUT'
TIMING_FILES_IN = 'CBHA_TIMING_FILES_IN'
_COLLECT_ERRORS = []


def pytest_collectreport(report):
    """Count the collection errors (a file that failed to import: its timing tests unknown)."""
    if report.failed:
        _COLLECT_ERRORS.append(report.nodeid)


def _collected_everything(config):
    """Return whether this session collected all of ``test/`` (no ``--lf`` skipping files)."""
    tests = REPO_ROOT / 'test'
    named = {Path(arg.split('::', 1)[0]).resolve() for arg in config.args}
    return tests in named and not config.getoption('lf', False) and not _COLLECT_ERRORS


def write_timing_files(path, timing):
    """Write the count of ``timing`` (items) and their files in collection order to ``path``."""
    files = list(dict.fromkeys(item.nodeid.split('::', 1)[0] for item in timing))
    path = Path(path)
    temporary = path.with_name(f'{path.name}.{os.getpid()}')
    temporary.write_text(''.join(f'{line}\n' for line in [len(timing), *files]))
    os.replace(temporary, path)     # the xdist workers both write it: whole or not at all


def check_timing_files(path, timing):
    """Fail the session unless ``timing`` holds as many tests as ``path`` counted."""
    expected = int(Path(path).read_text().split('\n', 1)[0])
    if len(timing) != expected:
        raise pytest.UsageError(
            f'{len(timing)} timing tests collected, {expected} in the first phase ({path}): '
            'a test file changed between the phases; run make test again')


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """
    Mark the timing tests ``timing`` (:func:`is_timing`), before ``-m`` selects on the marks.

    Run anyway under pytest-xdist (``pytest -n 2`` without ``-m``), they share one xdist group:
    one after the other on one worker, though no longer alone on the cores. Writes or checks the
    timing phase's files (:data:`TIMING_FILES_OUT`, :data:`TIMING_FILES_IN`).
    """
    timing = []
    for item in items:
        if is_timing(item):
            item.add_marker(pytest.mark.timing)
            item.add_marker(pytest.mark.xdist_group('timing'))
            timing.append(item)
    if os.environ.get(TIMING_FILES_OUT) and _collected_everything(config):
        write_timing_files(os.environ[TIMING_FILES_OUT], timing)
    if os.environ.get(TIMING_FILES_IN):
        check_timing_files(os.environ[TIMING_FILES_IN], timing)
    workerinput = getattr(config, 'workerinput', None)
    if workerinput is not None:
        # on pytest-xdist workers the files that took longest in earlier runs go first (each
        # file's tests together, in their order), so no long file starts last on one worker
        # while the other has nothing left; without earlier runs, those of TYPICAL_FILE_SECONDS
        seconds = {**TYPICAL_FILE_SECONDS, **workerinput.get(DURATIONS_KEY, {})}
        items.sort(key=lambda item: -seconds.get(item.nodeid.split('::', 1)[0], 0.0))


@pytest.hookimpl(optionalhook=True)
def pytest_configure_node(node):
    """Give each pytest-xdist worker the same file durations (:data:`DURATIONS_KEY`)."""
    cache = getattr(node.config, 'cache', None)
    if cache is not None:
        node.workerinput[DURATIONS_KEY] = cache.get(DURATIONS_KEY, {})


def pytest_runtest_logreport(report):
    """Add each test's set-up, call and teardown time to its file's (:data:`DURATIONS_KEY`)."""
    path = report.nodeid.split('::', 1)[0]
    _FILE_SECONDS[path] = _FILE_SECONDS.get(path, 0.0) + report.duration


def pytest_sessionfinish(session):
    """Store the files' durations of this run in pytest's cache (the main process only)."""
    cache = getattr(session.config, 'cache', None)
    if _FILE_SECONDS and cache is not None and not hasattr(session.config, 'workerinput'):
        cache.set(DURATIONS_KEY, {**cache.get(DURATIONS_KEY, {}), **_FILE_SECONDS})


def pytest_unconfigure(config):
    """Release the reserved domain id."""
    _RESERVATION.close()


@pytest.fixture(autouse=True)
def _timing_phase(request, monkeypatch):
    """Set ``CBHA_TEST_TIMING`` in a timing test (``ros_helpers.record_tracking`` checks it)."""
    if request.node.get_closest_marker('timing') is not None:
        monkeypatch.setenv('CBHA_TEST_TIMING', '1')
    else:
        monkeypatch.delenv('CBHA_TEST_TIMING', raising=False)


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


def _build_inputs(package):
    """
    Return a digest of what an interface build is made from.

    The shipped package's files, the pins of the environment (requirements and constraints) and
    the interpreter: a build made from the same inputs is the same build.
    """
    from cbha_inverse.interfaces.colcon_build import SHIPPED
    digest = hashlib.sha256(sys.executable.encode())
    source = SHIPPED / package
    files = sorted(path for path in source.rglob('*') if path.is_file())
    files += sorted(REPO_ROOT.glob('requirements*.txt')) + [REPO_ROOT / 'constraints.txt']
    for path in files:
        digest.update(str(path.relative_to(REPO_ROOT)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def _built_once(tmp_path_factory, package, build):
    """
    Build an interface package once and load it here; return its install prefix.

    ``build(workspace) -> prefix`` runs once per pytest run, or once per set of inputs
    (:func:`_build_inputs`) when ``CBHA_TEST_SHARED`` names a folder that runs share (``make
    test`` keeps it in the venv): the pytest-xdist workers and the phases take a lock, the first
    builds, the others load what it built; a later ``make test`` loads it again unless the
    package's files or the pins changed.
    """
    from ros_helpers import load_interface
    shared = os.environ.get('CBHA_TEST_SHARED')
    if shared is None and os.environ.get('PYTEST_XDIST_WORKER') is None:
        return load_interface(build(tmp_path_factory.mktemp(f'{package}_ws')))
    # the workers of one xdist run have base temporary folders with one parent
    shared = Path(shared) if shared is not None else tmp_path_factory.getbasetemp().parent
    built = shared / f'{package}_ws' / 'built'
    inputs = _build_inputs(package)
    with open(shared / f'{package}_ws.lock', 'w') as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if built.exists():
            prefix, _, made_from = built.read_text().partition('\n')
            if made_from == inputs and Path(prefix).is_dir():
                return load_interface(Path(prefix))
            built.unlink()
        prefix = build(shared / f'{package}_ws')
        built.write_text(f'{prefix}\n{inputs}')
        return load_interface(prefix)


@pytest.fixture(scope='session')
def robotino_msgs(tmp_path_factory):
    """
    Make ``robotino_msgs`` usable: the installed one (``make install``), else build the copy.

    Returns None for an installed package, else the install prefix of a colcon build made once
    per run (loaded in this process); ``robotino_helpers.robotino_child_env(prefix)`` gives
    child processes either environment.
    """
    import importlib.util
    if importlib.util.find_spec('robotino_msgs') is not None:
        return None
    from cbha_inverse.interfaces.robotino_msgs_build import build_robotino_msgs
    return _built_once(tmp_path_factory, 'robotino_msgs', build_robotino_msgs)


@pytest.fixture(scope='session')
def tf2_msgs(tmp_path_factory):
    """
    Make ``tf2_msgs`` usable: the installed one (``make install``, a sourced ROS 2), else build.

    Returns None for an installed package, else the install prefix of a colcon build made once
    (loaded in this process; ``interface_environment(prefix, child_env())`` for child processes).
    """
    import importlib.util
    if importlib.util.find_spec('tf2_msgs') is not None:
        return None
    from cbha_inverse.interfaces.tf2_msgs_build import build_tf2_msgs
    return _built_once(tmp_path_factory, 'tf2_msgs', build_tf2_msgs)
