"""Typed segment geometry files: the YAML's values, defaults, and one error line per bad key."""

from pathlib import Path

from cbha_inverse.errors import ConfigError
from cbha_inverse.fem.segment_spec import (BellowsGeometry, CylinderGeometry, read_segment_spec,
                                           Tube)
from cbha_inverse.paths import meshes_path
import pytest
import yaml

TEST_DATA = Path(__file__).resolve().parents[1] / 'data'
GEOMETRIES = {'cbha': meshes_path('cbha_segment_geometry.yaml'),
              'cylinder': TEST_DATA / 'cylinder_segment_geometry.yaml'}


@pytest.mark.parametrize('name', sorted(GEOMETRIES))
def test_spec_holds_exactly_the_values_of_the_file(name):
    raw = yaml.safe_load(GEOMETRIES[name].read_text())
    spec = read_segment_spec(GEOMETRIES[name])
    assert (spec.name, spec.kind) == (raw['name'], raw['kind'])
    assert spec.material.as_dict() == raw['material']
    assert (spec.mesh.mesh_size, spec.mesh.order) == (raw['mesh']['mesh_size'],
                                                      raw['mesh']['order'])
    shape = dict(raw['geometry'])
    if raw['kind'] == 'bellows_segment':
        assert isinstance(spec.geometry, BellowsGeometry)
        assert spec.geometry.tubes == tuple(Tube(**tube) for tube in shape.pop('tubes'))
        g = spec.geometry
        assert g.wall_end - g.wall_start == pytest.approx(
            shape['segment_length'] - shape['vertebra_thickness'], abs=1e-15)
    else:
        assert isinstance(spec.geometry, CylinderGeometry)
    for key, value in shape.items():
        assert getattr(spec.geometry, key) == value, key
    with pytest.raises(AttributeError):
        spec.geometry.segment_length = 1.0


def test_optional_keys_take_their_documented_defaults(tmp_path):
    text = GEOMETRIES['cbha'].read_text()
    stripped = '\n'.join(line for line in text.splitlines()
                         if not line.strip().startswith(('vertebra_mass:', 'order:',
                                                         'density:')))
    path = tmp_path / 'geometry.yaml'
    path.write_text(stripped)
    spec = read_segment_spec(path)
    assert (spec.geometry.vertebra_mass, spec.mesh.order, spec.material.density) == (0.0, 2, 0.0)


@pytest.mark.parametrize('old, new, message', [
    ('- {name: right, angle_deg: 210.0}', '- {name: right, angle_deg: south}',
     r'geometry\.tubes\[1\]\.angle_deg: must be a number'),
    ('corrugation_periods: 1', 'corrugation_periods: 0',
     r'geometry\.corrugation_periods: must be >= 1'),
    ('vertebra_thickness: 0.0025', 'vertebra_thickness: 0.02',
     r'geometry\.vertebra_thickness: must be below segment_length'),
    ('order: 2', 'order: 3', r'mesh\.order: must be 1 or 2, got 3'),
])
def test_a_bad_bellows_file_names_the_file_and_the_key(tmp_path, old, new, message):
    text = GEOMETRIES['cbha'].read_text()
    assert old in text
    path = tmp_path / 'geometry.yaml'
    path.write_text(text.replace(old, new))
    with pytest.raises(ConfigError, match=rf'^{path}: {message}'):
        read_segment_spec(path)
