"""
``realtime_priority``: the control thread under SCHED_FIFO, the threads started before it not.

The priority is set in child processes: a test process whose thread ran under SCHED_FIFO would
take a core from the other tests' nodes.
"""

import os
import subprocess
import sys
import textwrap

from cbha_inverse.ros.common.realtime import MAX_REALTIME_PRIORITY, set_realtime_priority
import pytest
from ros_helpers import child_env, interrupt, reaped, start_node, wait_for_line

# a thread started before and one started after the priority is set, and their policies
THREADS = textwrap.dedent("""
    import os, threading
    from cbha_inverse.ros.common.realtime import set_realtime_priority
    started = threading.Event()
    release = threading.Event()
    ids = {}

    def worker(name):
        ids[name] = threading.get_native_id()
        started.set()
        release.wait()

    before = threading.Thread(target=worker, args=('before',))
    before.start(); started.wait(); started.clear()
    refused = set_realtime_priority(int(os.environ['PRIORITY']))
    after = threading.Thread(target=worker, args=('after',))
    after.start(); started.wait()
    main = threading.get_native_id()
    print(refused)
    for name, tid in (('main', main), ('before', ids['before']), ('after', ids['after'])):
        print(name, os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority)
    release.set()
    """)


def _threads(priority):
    env = child_env()
    env['PRIORITY'] = str(priority)
    result = subprocess.run([sys.executable, '-c', THREADS], env=env,
                            capture_output=True, text=True, timeout=60, cwd='/')
    assert result.returncode == 0, result.stderr
    refused, *lines = result.stdout.splitlines()
    policies = {name: (int(policy), int(value))
                for name, policy, value in (line.split() for line in lines)}
    return (None if refused == 'None' else refused), policies


def _may_set_fifo():
    """Whether this process may use SCHED_FIFO (root or CAP_SYS_NICE; a child tries it)."""
    probe = ('import os; os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))')
    return subprocess.run([sys.executable, '-c', probe], capture_output=True).returncode == 0


needs_fifo = pytest.mark.skipif(not _may_set_fifo(),
                                reason='this machine refuses SCHED_FIFO to this user')


@pytest.mark.parametrize('priority', [-1, MAX_REALTIME_PRIORITY + 1, 1.5, True, '50'])
def test_a_priority_outside_0_to_98_is_refused(priority):
    with pytest.raises(ValueError, match='realtime priority must be an integer'):
        set_realtime_priority(priority)


def test_priority_0_leaves_every_thread_to_the_normal_scheduler():
    refused, policies = _threads(0)
    assert refused is None
    assert policies == {name: (os.SCHED_OTHER, 0) for name in ('main', 'before', 'after')}


@needs_fifo
def test_the_calling_thread_and_the_threads_it_starts_run_under_fifo():
    refused, policies = _threads(20)
    assert refused is None
    assert policies == {'main': (os.SCHED_FIFO, 20), 'before': (os.SCHED_OTHER, 0),
                        'after': (os.SCHED_FIFO, 20)}


@needs_fifo
def test_inverse_solver_runs_its_control_thread_under_fifo():
    process = start_node('cbha_inverse.ros.nodes.inverse_solver', '-r', '__ns:=/realtime',
                         '-p', 'realtime_priority:=30')
    with reaped(process):
        _, lines = wait_for_line(process, 'control thread:', 90.0)
        assert lines and 'control thread: SCHED_FIFO priority 30' in lines[-1], ''.join(lines)
        # the node's main thread (its executor's), and none of the DDS threads it started
        # before the priority was set
        assert os.sched_getscheduler(process.pid) == os.SCHED_FIFO
        assert os.sched_getparam(process.pid).sched_priority == 30
        dds = [int(tid) for tid in os.listdir(f'/proc/{process.pid}/task')
               if open(f'/proc/{process.pid}/task/{tid}/comm').read().startswith('dds.')]
        assert dds and all(os.sched_getscheduler(tid) == os.SCHED_OTHER for tid in dds)
        output, _ = interrupt(process)
    assert process.returncode == 0, ''.join(lines) + output
