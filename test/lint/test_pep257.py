"""The real ament_pep257 docstring linter over the package and its tests."""

from pathlib import Path

from ament_pep257.main import main
import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    """Every docstring passes ament_pep257 (ROS 2 Jazzy's configuration)."""
    paths = [str(REPO_ROOT / name) for name in ('cbha_inverse', 'test', 'setup.py')]
    # ament_pep257 skips folders whose names start with '_' (the compiled kernels): name their
    # files one by one
    paths += sorted(str(path) for path in (REPO_ROOT / 'cbha_inverse').rglob('_*/*.py'))
    rc = main(argv=paths)
    assert rc == 0, 'Found code style errors / warnings'
