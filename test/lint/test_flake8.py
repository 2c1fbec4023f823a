"""The real ament_flake8 linter over the package, its tests and setup.py."""

from pathlib import Path

from ament_flake8.main import main_with_errors
import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    """Every Python file passes ament_flake8 (ROS 2 Jazzy's configuration)."""
    paths = [str(REPO_ROOT / name) for name in ('cbha_inverse', 'test', 'setup.py')]
    # ament_flake8 skips folders whose names start with '_' (the compiled kernels): name their
    # files one by one
    paths += sorted(str(path) for path in (REPO_ROOT / 'cbha_inverse').rglob('_*/*.py'))
    rc, errors = main_with_errors(argv=paths)
    assert rc == 0, f'Found {len(errors)} code style errors / warnings:\n' + '\n'.join(errors)
