"""
``make test``'s second phase collects only the files the first phase listed (test/conftest.py).

The first phase writes the number of timing tests and their files; the second fails unless it
collects as many, so a timing test in a file missing from the list cannot be skipped unseen.
"""

from types import SimpleNamespace

import conftest
import pytest


def _items(*nodeids):
    return [SimpleNamespace(nodeid=nodeid) for nodeid in nodeids]


def test_the_list_holds_the_count_and_each_file_once_in_collection_order(tmp_path):
    listed = tmp_path / 'timing-files'
    timing = _items('test/system/b.py::t1', 'test/system/b.py::t2[x]', 'test/ros/a.py::t')
    conftest.write_timing_files(listed, timing)
    assert listed.read_text() == '3\ntest/system/b.py\ntest/ros/a.py\n'
    assert [p.name for p in tmp_path.iterdir()] == ['timing-files']    # no temporary file left
    conftest.check_timing_files(listed, timing)
    with pytest.raises(pytest.UsageError, match='2 timing tests collected, 3 in the first'):
        conftest.check_timing_files(listed, timing[:2])


def test_the_list_is_written_only_from_a_whole_collection(monkeypatch):
    def config(args, lf=False):
        return SimpleNamespace(args=args, getoption=lambda name, default=None: lf)

    tests = str(conftest.REPO_ROOT / 'test')
    assert conftest._collected_everything(config([tests]))
    assert not conftest._collected_everything(config([tests + '/ros']))
    assert not conftest._collected_everything(config([tests], lf=True))
    monkeypatch.setattr(conftest, '_COLLECT_ERRORS', ['test/ros/test_broken.py'])
    assert not conftest._collected_everything(config([tests]))
