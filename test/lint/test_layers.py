"""
The package's layers: what may import what, and text that cites outside places.

Layers, bottom to top (:data:`LAYERS`); a module may import its own layer and the ones below,
never one above. Imports are read with :mod:`ast` from every ``.py`` file of the package,
function-local ones included; ``from a.b import c`` counts as importing ``a.b.c`` when that is a
module. A string that is exactly a package module's dotted name (``python -m``, an
``importlib.import_module`` call, a table of modules to run) is a use of that module too.
Compiled code and ROS are confined: only ``core/_kernels`` imports numba; only ``ros/``,
``report/bench_bag.py`` and ``experiments/`` import rclpy or ROS message packages.
"""

import ast
from pathlib import Path
import re

import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]
PACKAGE = 'cbha_inverse'
PACKAGE_DIR = REPO_ROOT / PACKAGE

LAYERS = (
    ('errors', 'paths', 'config_files', 'core._kernels'),
    ('core',),
    ('fem', 'vision', 'metrics'),
    ('scene',),
    ('sim', 'robot', 'bag', 'identify', 'estimate'),
    ('ros', 'interfaces', 'warmup', 'report'),
    ('experiments',),
)
"""Parts of the package (relative dotted names), bottom layer first."""

NUMBA_HOMES = ('core/_kernels/',)
"""Where numba may be imported (relative to the package folder; a folder ends with /)."""

ROS_HOMES = ('ros/', 'report/bench_bag.py', 'report/bench_node.py', 'experiments/')
"""Where rclpy and ROS message packages may be imported."""

ROS_PACKAGE = re.compile(r'^(rclpy|builtin_interfaces|rosidl_\w+|\w+_msgs|\w+_srvs)$')
"""Top-level names of rclpy and of the ROS interface (message and service) packages."""

OUTSIDE_REFERENCE = re.compile('|'.join(('DESI' 'GN', '\u00a7', 'shared' '/', 'issue [0-9]')))
"""
Citations of places a user of the package does not have: the design notes' name and section sign,
the notes folder next to the repository, issue numbers (spelled in pieces: this file does not
match itself).
"""

SELF_CONTAINED = ('cbha_inverse', 'config', 'launch', 'docs', 'README.md')
"""What must explain itself without those places (folders and files of the repository)."""


def _modules():
    """Return ``{dotted name: path}`` of every module of the package (packages by __init__)."""
    modules = {}
    for path in sorted(PACKAGE_DIR.rglob('*.py')):
        parts = path.relative_to(REPO_ROOT).with_suffix('').parts
        if parts[-1] == '__init__':
            parts = parts[:-1]
        modules['.'.join(parts)] = path
    return modules


MODULES = _modules()


def _relative(path):
    return path.relative_to(PACKAGE_DIR).as_posix()


def _layer(module):
    """
    Return the layer index of a package module, or None for the package's own ``__init__``.

    Raises
    ------
    AssertionError
        If the module belongs to no layer (a new part of the package must be placed in one).

    """
    if module == PACKAGE:
        return None
    name = module[len(PACKAGE) + 1:]
    # the longest matching part decides: core._kernels lies below the rest of core
    matches = [(len(part), index) for index, layer in enumerate(LAYERS) for part in layer
               if name == part or name.startswith(part + '.')]
    assert matches, f'{module} is in no layer of LAYERS'
    return max(matches)[1]


def _imports(module, path):
    """Yield ``(line, imported dotted name)`` of every import statement of a module."""
    is_package = path.name == '__init__.py'
    tree = ast.parse(path.read_text(encoding='utf-8'), str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split('.')
                base = base[:len(base) - node.level + is_package]
                source = '.'.join(base + ([node.module] if node.module else []))
            else:
                source = node.module
            for alias in node.names:
                submodule = f'{source}.{alias.name}'
                yield node.lineno, submodule if submodule in MODULES else source
        elif (isinstance(node, ast.Constant) and isinstance(node.value, str)
              and node.value in MODULES):
            yield node.lineno, node.value


def _package_imports():
    """Yield ``(module, path, line, imported)`` over the whole package."""
    for module, path in MODULES.items():
        for line, imported in _imports(module, path):
            yield module, path, line, imported


def test_layers_cover_every_module():
    """Every module lies in one layer, and every part of LAYERS exists."""
    for module in MODULES:
        _layer(module)
    for part in (p for layer in LAYERS for p in layer):
        assert f'{PACKAGE}.{part}' in MODULES, f'LAYERS names {part}, which does not exist'


def test_no_module_imports_a_layer_above_its_own():
    upward = []
    for module, path, line, imported in _package_imports():
        if imported != PACKAGE and imported.startswith(PACKAGE + '.'):
            own, other = _layer(module), _layer(imported)
            if own is not None and other is not None and other > own:
                upward.append(f'{_relative(path)}:{line}: {imported} (layer {other} > {own})')
    assert not upward, 'imports of a higher layer:\n' + '\n'.join(upward)


def test_package_init_imports_nothing_of_the_package():
    """``import cbha_inverse.<anything>`` runs the package's __init__: it must stay bottom."""
    path = MODULES[PACKAGE]
    inside = [f'{line}: {name}' for line, name in _imports(PACKAGE, path)
              if name.startswith(PACKAGE)]
    assert not inside, f'{_relative(path)} imports ' + ', '.join(inside)


@pytest.mark.parametrize('what, pattern, homes', [
    ('numba', re.compile(r'^numba$'), NUMBA_HOMES),
    ('rclpy or a ROS message package', ROS_PACKAGE, ROS_HOMES),
])
def test_compiled_code_and_ros_stay_in_their_homes(what, pattern, homes):
    found = []
    for _, path, line, imported in _package_imports():
        top = imported.split('.')[0]
        where = _relative(path)
        if pattern.match(top) and not any(
                where.startswith(home) if home.endswith('/') else where == home
                for home in homes):
            found.append(f'{where}:{line}: {imported}')
    assert not found, f'{what} imported outside {", ".join(homes)}:\n' + '\n'.join(found)


def test_ros_package_holds_only_subpackages():
    """``cbha_inverse/ros/`` is sorted by kind: nodes/, common/, bag/, launch/, console/."""
    flat = sorted(p.name for p in (PACKAGE_DIR / 'ros').glob('*.py') if p.name != '__init__.py')
    assert not flat, f'modules directly in cbha_inverse/ros/: {flat}'


def _text_files(root):
    """Yield every text file under ``root`` (a folder or one file), caches and binaries skipped."""
    paths = [root] if root.is_file() else sorted(p for p in root.rglob('*') if p.is_file())
    for path in paths:
        if '__pycache__' in path.parts:
            continue
        try:
            yield path, path.read_text(encoding='utf-8')
        except UnicodeDecodeError:
            continue


def test_package_config_and_docs_cite_nothing_outside_the_repository():
    """No design-note sections, paths outside the repository, issue numbers: it explains itself."""
    found = []
    for name in SELF_CONTAINED:
        for path, text in _text_files(REPO_ROOT / name):
            for number, line in enumerate(text.splitlines(), 1):
                if OUTSIDE_REFERENCE.search(line):
                    found.append(f'{path.relative_to(REPO_ROOT)}:{number}: {line.strip()}')
    assert not found, f'{len(found)} lines cite outside places:\n' + '\n'.join(found)
