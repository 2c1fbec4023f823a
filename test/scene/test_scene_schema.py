"""The scene file reference: generated from the declaration the loader checks, never drifting."""

import inspect
from pathlib import Path
import re

from cbha_inverse.config_files import ConfigError, read_yaml
from cbha_inverse.paths import config_path
import cbha_inverse.scene as scene_package
from cbha_inverse.scene import load_scene
from cbha_inverse.scene.cli import main as scene_main
from cbha_inverse.scene.schema import BLOCKS, keys, markdown
import pytest
import yaml

REPO = Path(__file__).resolve().parents[2]
PAGE = REPO / 'docs' / 'scene-schema.md'
SCENE_MODULES = sorted(Path(inspect.getfile(scene_package)).parent.glob('*.py'))


def test_the_page_is_the_declaration(capsys):
    """docs/scene-schema.md is what ``cbha_scene schema`` prints (regenerate it if not)."""
    assert scene_main(['schema']) == 0
    printed = capsys.readouterr().out
    assert printed == markdown()
    assert PAGE.read_text() == printed, 'run: cbha_scene schema > docs/scene-schema.md'


def test_every_key_check_of_the_loader_reads_the_declaration():
    """No ``only(...)`` with literal key names in the scene modules: they all ask the schema."""
    for module in SCENE_MODULES:
        literal = re.findall(r"\.only\(\s*'", module.read_text())
        assert not literal, f'{module.name} checks keys it does not declare in scene.schema'


def test_every_declared_key_says_what_it_is():
    for block in BLOCKS.values():
        assert block.summary
        for key in block.keys:
            assert key.meaning.strip(), f'{block.path}.{key.name}'
        assert len(keys(block.path)) == len(set(keys(block.path))), block.path


@pytest.mark.parametrize('edit, key, nearest', [
    (lambda spec: spec.update(gravty=[0.0, 0.0, 0.0]), 'gravty', 'gravity'),
    (lambda spec: spec['effectors'][0].update(ofset=[0.0, 0.0, 0.0]), 'effectors[0].ofset',
     'offset'),
    (lambda spec: spec['chain']['backbone'].update(youngs_modulos=1e7),
     'chain.backbone.youngs_modulos', 'youngs_modulus'),
    (lambda spec: spec.update(loads=[{'name': 'a', 'frame': 'tip', 'forse': [0, 0, 1]}]),
     'loads[0].forse', 'force'),
    (lambda spec: spec.update(solver={'energy_weigth': 1e-6}), 'solver.energy_weigth',
     'energy_weight'),
])
def test_a_misspelt_key_is_refused_with_the_nearest_declared_name(tmp_path, edit, key, nearest):
    spec = read_yaml(config_path('scenes', 'tendon_6f_8c.yaml'))
    edit(spec)
    path = tmp_path / 'misspelt.yaml'
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    with pytest.raises(ConfigError) as info:
        load_scene(path)
    assert info.value.key == key
    assert info.value.problem == f"unknown key, did you mean '{nearest}'?"
