"""
Configuration files and parameters: defaults, ``--help``, and one clear line for every mistake.

Every YAML the package reads (scene, segment, geometry, params, camera) fails with one line naming
the file, the key or line and what is wrong (an unknown key: with the nearest valid one), exit
code 2, for nodes (real processes) and commands
alike; ``<node> --help`` lists the node's parameters and exits 0 without starting ROS; the code
defaults equal the shipped params files.
"""

from dataclasses import fields, is_dataclass
import importlib
from pathlib import Path
import re
import shutil
import subprocess
import sys

from cbha_inverse.config_files import read_yaml
from cbha_inverse.errors import ConfigError
from cbha_inverse.fem.cli import main as condense_main
from cbha_inverse.paths import config_path, meshes_path
from cbha_inverse.scene import load_scene
import pytest
from ros_helpers import child_env, REPO_ROOT

CYLINDER_YAML = Path(__file__).resolve().parents[1] / 'data' / 'cylinder_segment_geometry.yaml'
SCRIPT = re.compile(r"'(\w+) = (cbha_inverse\.ros\.nodes\.\w+):main'")
NODES = dict(SCRIPT.findall((REPO_ROOT / 'setup.py').read_text()))
# the lifecycle variants (<node>_managed) share their node's parameters and params file
PLAIN_NODES = sorted(node for node in NODES if not node.endswith('_managed'))


def plain_module(node):
    """Return the module of ``node``'s parameters (a managed variant: its plain node's)."""
    return NODES[node.removesuffix('_managed')]


def params_class(module_name):
    """Return the parameters dataclass of a node module (``<Node>Params``)."""
    module = importlib.import_module(module_name)
    found = [value for name, value in vars(module).items()
             if name.endswith('Params') and is_dataclass(value)
             and value.__module__ == module.__name__]
    assert len(found) == 1, f'{module_name} has {len(found)} *Params dataclasses'
    return found[0]


def _file_parameters(node):
    return read_yaml(config_path(f'{node}.yaml'))['/**']['ros__parameters']


def test_every_node_has_a_console_script():
    assert {'trajectory', 'inverse_solver', 'cbha_sim'} <= set(NODES)


FILE_ONLY = {('inverse_solver', 'reach_samples'): 1000}
"""Shipped values that differ from the code's on purpose: a bare node (and every test) samples
no reachable set (~1.4 s on the CBHA), a launched one checks goals against 1000 samples."""


@pytest.mark.parametrize('node', PLAIN_NODES)
def test_code_defaults_equal_the_shipped_params_file(node):
    shipped = _file_parameters(node)
    declared = {spec.metadata.get('ros_name') or spec.name: spec.default
                for spec in fields(params_class(NODES[node]))}
    with_default = {name for name, default in declared.items() if default is not None}
    assert set(shipped) <= set(declared), f'unknown in the file: {set(shipped) - set(declared)}'
    assert with_default <= set(shipped), f'not in the file: {with_default - set(shipped)}'
    for name, value in shipped.items():
        default = FILE_ONLY.get((node, name), declared[name])
        expected = list(default) if isinstance(default, tuple) else default
        assert value == expected and type(value) is type(expected), (
            f'{node}.{name}: file {value!r}, code {default!r}')


def _run(args, **kwargs):
    return subprocess.Popen([sys.executable, *args], cwd=REPO_ROOT, env=child_env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kwargs)


def test_every_node_answers_help_without_starting():
    processes = {node: _run(['-m', module, '--help']) for node, module in NODES.items()}
    for node, process in processes.items():
        out, err = process.communicate(timeout=120)
        assert process.returncode == 0, f'{node} --help: exit {process.returncode}\n{err}'
        assert out.startswith(f'usage: {node}'), out
        for spec in fields(params_class(plain_module(node))):
            name = spec.metadata.get('ros_name') or spec.name
            entry = re.search(rf'^  {re.escape(name)} \((\w+), default ([^\n]*)\)\n      (.+)$',
                              out, re.MULTILINE)
            assert entry, f'{node} --help does not describe {name}:\n{out}'
            low = spec.metadata.get('low')
            if low is not None:
                assert f'range [{low:g}, ' in entry.group(2)
            assert entry.group(2).endswith(', live' if spec.metadata['live'] else ', read-only')
        assert '[INFO]' not in out + err, f'{node} started instead of printing help'


def _one_line(err):
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, f'expected one line, got:\n{err}'
    return lines[0]


@pytest.fixture(scope='module')
def broken_files(tmp_path_factory):
    """Write the broken files of the node and command cases."""
    folder = tmp_path_factory.mktemp('broken')
    files = {
        'bad_yaml_scene': 'name: bad\nchain:\n  type: segments\n  sections: [{name: a\n',
        'no_chain_scene': 'name: no_chain\neffectors: [{name: tip}]\n',
        'bad_params': '/**:\n  ros__parameters:\n    rate_hz: 100\n',
        'broken_params': '/**:\n  ros__parameters:\n    rate_hz: [1.0\n',
        'bad_section_params': '/**:\n  rate_hz: 100.0\n',
        'no_model_camera': 'image_width: 640\nimage_height: 480\n',
        'no_camera_rig': 'base_from_left: [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]\n',
        'typo_params': '/**:\n  ros__parameters:\n    use_sim_time: true\n    loop_gian: 0.3\n',
    }
    paths = {}
    for name, text in files.items():
        paths[name] = folder / f'{name}.yaml'
        paths[name].write_text(text)
    paths['missing'] = folder / 'missing.yaml'
    return paths


NODE_CASES = [
    ('inverse_solver', ['-p', 'scene:={bad_yaml_scene}'], r'bad_yaml_scene\.yaml: line 5: '),
    ('cbha_sim', ['-p', 'scene:={bad_yaml_scene}'], r'bad_yaml_scene\.yaml: line 5: '),
    ('inverse_solver', ['-p', 'scene:={no_chain_scene}'], r'no_chain_scene\.yaml: chain: missing'),
    ('cbha_sim', ['-p', 'scene:={no_chain_scene}'], r'no_chain_scene\.yaml: chain: missing'),
    ('inverse_solver', ['--params-file', '{bad_params}'],
     r'bad_params\.yaml: /\*\*\.ros__parameters\.rate_hz: must be of type double \(write '
     r'floats with a decimal point'),
    ('trajectory', ['--params-file', '{broken_params}'], r'broken_params\.yaml: line \d: '),
    ('cbha_sim', ['--params-file', '{bad_section_params}'],
     r'bad_section_params\.yaml: /\*\*: must hold a ros__parameters'),
    ('trajectory', ['--params-file', '{missing}'], r'missing\.yaml: file: no such file'),
    ('inverse_solver', ['-p', 'rate_hz:=100'],
     r"parameter 'rate_hz' must be of type double \(write floats"),
    ('inverse_solver', ['-p', 'scene:=no_such_scene'], r'no scene no_such_scene'),
    ('stereo_tracker', ['-p', 'left_camera_info_file:={no_model_camera}'],
     r'no_model_camera\.yaml: distortion_model: missing'),
    ('cbha_sim', ['-p', 'tip_output:=stereo', '-p', 'camera_rig:={no_camera_rig}'],
     r'no_camera_rig\.yaml: left_camera_info: missing'),
    ('inverse_solver', ['--params-file', '{typo_params}'],
     r'typo_params\.yaml: /\*\*\.ros__parameters\.loop_gian: unknown parameter of '
     r"inverse_solver, did you mean 'loop_gain'\?$"),
    ('trajectory', ['-p', 'bogus:=1'], r'-p bogus:=1: unknown parameter of trajectory \(valid: '),
    ('cbha_sim', ['-p', 'use_sim_time:=true', '-p', 'noise_sdt:=0.0'],
     r"-p noise_sdt:=0.0: unknown parameter of cbha_sim, did you mean 'noise_std'\?$"),
]


def test_nodes_exit_2_with_one_line_on_bad_configuration(broken_files):
    processes = []
    for node, args, pattern in NODE_CASES:
        args = [a.format(**broken_files) for a in args]
        processes.append((node, args, pattern, _run(['-m', NODES[node], '--ros-args', *args])))
    for node, args, pattern, process in processes:
        _, err = process.communicate(timeout=120)
        assert process.returncode == 2, f'{node} {args}: exit {process.returncode}\n{err}'
        line = _one_line(err)
        assert line.startswith(f'{node}: error: ') and re.search(pattern, line), line
        assert not line.startswith(f'{node}: error: {node}'), line


@pytest.mark.parametrize('text, key', [
    ('name: x\nchain: {type: spiral}\n', r'chain\.type: must be one of'),
    ('chain: {type: beam_vertebrae, n_vertebrae: three}\n', r'chain\.n_vertebrae: must be an '
     r"integer, got str 'three'"),
    ('chain:\n  type: segments\n  sections: [{name: a, segment: nowhere.yaml, count: 2}]\n',
     r'chain\.sections\[0\]\.segment: no segment file'),
    ('chain: {type: segments, sections: []}\n', r'chain\.sections: at least one section'),
    ('- just\n- a list\n', r'top level: must be a mapping'),
])
def test_scene_errors_name_the_key(tmp_path, text, key):
    path = tmp_path / 'scene.yaml'
    path.write_text(text)
    with pytest.raises(ConfigError, match=rf'^{re.escape(str(path))}: {key}'):
        load_scene(path)


def test_a_broken_segment_file_is_named_by_the_scene_that_reads_it(tmp_path):
    segment = tmp_path / 'seg.yaml'
    segment.write_text('compliance: [[1.0, 0.0], [0.0, 1.0]]\nrest_offset: [0.01, 0.0, 0.0]\n')
    text = config_path('scenes', 'tendon_6f_8c.yaml').read_text()
    scene_text = re.sub(r'chain:\n(  .*\n)+', 'chain:\n  type: segments\n  sections: '
                        '[{name: s, segment: seg.yaml, count: 2}]\n', text)
    assert 'n_vertebrae' not in scene_text
    (tmp_path / 'scene.yaml').write_text(scene_text)
    with pytest.raises(ConfigError, match=rf'^{re.escape(str(segment))}: compliance: must be a '
                       r'\(6, 6\) array'):
        load_scene(tmp_path / 'scene.yaml')


@pytest.mark.parametrize('edit, key', [
    (lambda text: text + 'mesh: [\n', r'line \d+: invalid YAML'),
    (lambda text: text.replace('mesh_size: 0.003', 'size: 0.003'),
     r"mesh\.size: unknown key, did you mean 'mesh_size'\?"),
    (lambda text: re.sub(r'\n +mesh_size: 0\.003', '', text), r'mesh\.mesh_size: missing'),
    (lambda text: text.replace('poisson_ratio: 0.3', 'poisson_ratio: 0.5'),
     r'material\.poisson_ratio: must lie in \(-1, 0\.5\)'),
    (lambda text: text.replace('kind: cylinder', 'kind: cone'), r'kind: must be one of'),
])
def test_condense_segment_exits_2_with_one_line(tmp_path, capsys, edit, key):
    geometry = tmp_path / 'geometry.yaml'
    geometry.write_text(edit(CYLINDER_YAML.read_text()))
    assert condense_main([str(geometry)]) == 2
    line = _one_line(capsys.readouterr().err)
    assert re.match(rf'condense_segment: error: {re.escape(str(geometry))}: {key}', line), line


def test_condense_segment_writes_next_to_its_input_or_to_output(tmp_path, capsys, monkeypatch):
    geometry = tmp_path / 'geometry.yaml'
    shutil.copy(CYLINDER_YAML, geometry)
    coarse = ['--mesh-size', '0.01', '--order', '1']
    assert condense_main([str(geometry), *coarse]) == 0
    assert (tmp_path / 'cylinder_segment.yaml').is_file()
    assert condense_main([str(geometry), '--output', str(tmp_path / 'out' / 'c.yaml'),
                          *coarse]) == 0
    assert (tmp_path / 'out' / 'c.yaml').is_file()
    same_name = tmp_path / 'cylinder_segment.yaml'
    shutil.copy(geometry, same_name)
    assert condense_main([str(same_name), *coarse]) == 2
    assert 'would overwrite the geometry file' in capsys.readouterr().err
    # the package's own geometry (the install tree of a colcon build): into the working folder,
    # named after its name: field (cbha_segment_geometry.yaml -> cbha_segment.yaml)
    work = tmp_path / 'work'
    work.mkdir()
    monkeypatch.chdir(work)
    before = sorted(Path(meshes_path()).iterdir())
    assert condense_main([str(meshes_path('cbha_segment_geometry.yaml')), '--mesh-size', '0.004',
                          '--order', '1']) == 0
    assert (work / 'cbha_segment.yaml').is_file()
    assert sorted(Path(meshes_path()).iterdir()) == before


def _tendon_scene(tmp_path, edit):
    path = tmp_path / 'scene.yaml'
    text = config_path('scenes', 'tendon_6f_8c.yaml').read_text()
    edited = edit(text)
    assert edited != text, 'the edit changed nothing'
    path.write_text(edited)
    return path


@pytest.mark.parametrize('edit, key, nearest', [
    (lambda t: t.replace('gravity:', 'gravty:'), 'gravty', 'gravity'),
    (lambda t: t.replace('n_vertebrae:', 'n_vertebra:'), 'chain.n_vertebra', 'n_vertebrae'),
    (lambda t: t.replace('outer_radius:', 'outer_radus:'), 'chain.backbone.outer_radus',
     'outer_radius'),
    (lambda t: t.replace('max_tension:', 'max_tensoin:', 1), 'cables[0].max_tensoin',
     'max_tension'),
    (lambda t: t.replace('offset:', 'ofset:', 1), 'effectors[0].ofset', 'offset'),
    (lambda t: t.replace('actuation_fraction:', 'actuation_fractoin:'),
     'workspace_center.actuation_fractoin', 'actuation_fraction'),
    (lambda t: t + 'solver:\n  tolerence: 1.0e-6\n', 'solver.tolerence', None),
])
def test_an_unknown_scene_key_names_the_nearest_valid_one(tmp_path, edit, key, nearest):
    path = _tendon_scene(tmp_path, edit)
    with pytest.raises(ConfigError) as info:
        load_scene(path)
    assert (info.value.path, info.value.key) == (str(path), key)
    assert info.value.problem.startswith('unknown key')
    if nearest:
        assert info.value.problem == f'unknown key, did you mean {nearest!r}?'


def test_unknown_keys_of_segment_geometry_and_camera_files_are_errors(tmp_path):
    from cbha_inverse.fem.segment_io import load_segment
    from cbha_inverse.fem.segment_spec import read_segment_spec
    from cbha_inverse.vision.camera import load_camera_yaml
    from cbha_inverse.vision.rig import load_rig
    cases = [
        (load_segment, config_path('segments', 'cbha_segment.yaml'), ('mass_kg:', 'mas_kg:'),
         'mas_kg', 'mass_kg'),
        (read_segment_spec, CYLINDER_YAML, ('poisson_ratio:', 'poison_ratio:'),
         'material.poison_ratio', 'poisson_ratio'),
        (load_camera_yaml, config_path('cameras', 'left.yaml'), ('camera_name:', 'camera_nme:'),
         'camera_nme', 'camera_name'),
        (load_camera_yaml, config_path('cameras', 'left.yaml'), ('  cols: 5', '  colls: 5'),
         'distortion_coefficients.colls', 'cols'),
        (load_rig, config_path('cameras', 'rig.yaml'), ('base_from_left:', 'base_from_lft:'),
         'base_from_lft', 'base_from_left'),
    ]
    for load, source, (old, new), key, nearest in cases:
        path = tmp_path / source.name
        for sibling in source.parent.iterdir():
            if sibling.suffix in ('.yaml', '.vtk'):
                shutil.copy(sibling, tmp_path / sibling.name)
        text = source.read_text()
        assert old in text, (source, old)
        path.write_text(text.replace(old, new, 1))
        with pytest.raises(ConfigError) as info:
            load(path)
        assert (info.value.path, info.value.key) == (str(path), key), info.value
        assert info.value.problem == f'unknown key, did you mean {nearest!r}?'
        shutil.copy(source, path)
        load(path)
