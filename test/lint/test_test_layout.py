"""
The test suite's folders mirror the package, and no two test files share a name.

A test file lives in ``test/<part>/``, where ``<part>`` is a part of the package (a subpackage or
a top-level module of ``cbha_inverse``: ``core``, ``fem``, ``ros``, ...) or one of the
:data:`CROSS_CUTTING` folders; folders without test files hold helpers and data. pytest imports
the test files in its default ``prepend`` mode (the folders have no ``__init__.py``): each file is
imported under its basename, so two files of one name would collide.
"""

from collections import defaultdict
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
TEST_DIR = REPO_ROOT / 'test'

CROSS_CUTTING = {'system': 'runs over real DDS, of installed executables and of the commands',
                 'lint': 'checks of the source tree (style, layers, this layout)'}
"""Test folders that are no part of the package, and what they hold."""


def _package_parts():
    """Return the names of the package's subpackages and top-level modules."""
    package = REPO_ROOT / 'cbha_inverse'
    return ({p.name for p in package.iterdir() if (p / '__init__.py').is_file()}
            | {p.stem for p in package.glob('*.py') if p.name != '__init__.py'})


def _test_files():
    return sorted(p for p in TEST_DIR.rglob('test_*.py') if '__pycache__' not in p.parts)


def test_every_test_file_is_in_the_folder_of_a_package_part():
    allowed = _package_parts() | set(CROSS_CUTTING)
    misplaced = []
    for path in _test_files():
        parts = path.relative_to(TEST_DIR).parts
        if len(parts) != 2 or parts[0] not in allowed:
            misplaced.append(str(path.relative_to(REPO_ROOT)))
    assert not misplaced, (f'test files outside test/<part>/ (parts: {sorted(allowed)}):\n'
                           + '\n'.join(misplaced))


def test_test_file_names_are_unique():
    folders = defaultdict(list)
    for path in _test_files():
        folders[path.name].append(path.parent.name)
    repeated = {name: where for name, where in folders.items() if len(where) > 1}
    assert not repeated, f'test file names used more than once: {repeated}'
