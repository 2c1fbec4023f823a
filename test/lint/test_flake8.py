"""The real ament_flake8 linter over the package, its tests and setup.py."""

import contextlib
from pathlib import Path

from ament_flake8.main import main_with_errors
import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]


@contextlib.contextmanager
def untraced():
    """
    Pause the coverage measurements of this process (``make test``), if any, in the block.

    For a linter: it runs none of the package's code, and flake8's forked workers would inherit
    the line tracer (its CPU time 41 s instead of 19 s, measured on the 2-core machine). A
    pytest-xdist worker runs two: pytest-cov's, and the one its start as a child process began
    (``patch = subprocess``), which runs again when the first stops; so every one is stopped.
    """
    try:
        import coverage
    except ImportError:
        yield
        return
    stopped = []
    while coverage.Coverage.current() is not None:
        stopped.append(coverage.Coverage.current())
        stopped[-1].stop()
    try:
        yield
    finally:
        for measuring in reversed(stopped):
            measuring.start()


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    """Every Python file passes ament_flake8 (ROS 2 Jazzy's configuration)."""
    paths = [str(REPO_ROOT / name) for name in ('cbha_inverse', 'test', 'setup.py')]
    # ament_flake8 skips folders whose names start with '_' (the compiled kernels): name their
    # files one by one
    paths += sorted(str(path) for path in (REPO_ROOT / 'cbha_inverse').rglob('_*/*.py'))
    with untraced():
        rc, errors = main_with_errors(argv=paths)
    assert rc == 0, f'Found {len(errors)} code style errors / warnings:\n' + '\n'.join(errors)
