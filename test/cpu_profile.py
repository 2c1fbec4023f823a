"""
A pytest plugin: each test's wall time and CPU time, its own and its child processes'.

``PYTHONPATH=test .venv/bin/python -m pytest -p cpu_profile ...`` writes one line per test to
``CBHA_TEST_CPU_PROFILE`` (default ``cpu_profile.tsv``; ``.<worker>`` appended on a
pytest-xdist worker): node id, then wall, own CPU and children's CPU [s] of its set-up, call and
teardown (a module fixture counts for the first test that uses it). Children are counted when
they were waited for (``subprocess.run``, ``Popen.wait``); what wall time neither accounts for
was spent waiting: for messages, discovery, a fixed run time, or the cores other processes held.
"""

import os
import resource
import time

import pytest

_ROWS = []


def _cpu_seconds():
    """Return this process's and its waited-for children's user + system time [s]."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, children.ru_utime + children.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """Time one test's set-up, call and teardown."""
    wall = time.monotonic()
    own, children = _cpu_seconds()
    yield
    own_after, children_after = _cpu_seconds()
    _ROWS.append((item.nodeid, time.monotonic() - wall, own_after - own,
                  children_after - children))


def pytest_sessionfinish(session):
    """Write the rows (see the module docstring)."""
    if not _ROWS:
        return
    path = os.environ.get('CBHA_TEST_CPU_PROFILE', 'cpu_profile.tsv')
    worker = os.environ.get('PYTEST_XDIST_WORKER')
    with open(f'{path}.{worker}' if worker else path, 'w', encoding='utf-8') as out:
        for row in _ROWS:
            out.write('%s\t%.2f\t%.2f\t%.2f\n' % row)
