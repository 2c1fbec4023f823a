"""
``condense_segment``'s cache: every input that enters the sha256 invalidates it, nothing else.

The hash covers the geometry file's bytes, the element order, the mesh size and the package
version (for a ``.geo`` file also the material and the segment length). Each case changes one
input and checks that the segment is recomputed: a new ``inputs_sha256`` equal to an
independent sha256 of the new inputs and, where the change alters the physics, the compliance
it must have (linear elasticity: doubling E halves C exactly up to round-off).
"""

import hashlib
import json
from pathlib import Path

from cbha_inverse import __version__
from cbha_inverse.fem.cli import main
from cbha_inverse.fem.segment_io import inputs_sha256, load_segment
from cbha_inverse.paths import meshes_path
import numpy as np
import pytest
import yaml

CYLINDER_YAML = Path(__file__).resolve().parents[1] / 'data' / 'cylinder_segment_geometry.yaml'
MESH = ['--mesh-size', '0.006', '--order', '1']


def _independent_sha(geometry, order, mesh_size, version=__version__):
    digest = hashlib.sha256(geometry.read_bytes())
    digest.update(json.dumps({'mesh_size': float(mesh_size), 'order': int(order),
                              'version': str(version)}, sort_keys=True).encode())
    return digest.hexdigest()


def _run(capsys, *args):
    assert main([str(a) for a in args]) == 0
    return capsys.readouterr().out


@pytest.fixture
def cylinder(tmp_path):
    """Return a private copy of the cylinder geometry YAML and the segment path it gives."""
    geometry = tmp_path / 'cylinder_segment_geometry.yaml'
    geometry.write_bytes(CYLINDER_YAML.read_bytes())
    return geometry, tmp_path / 'out' / 'cylinder_segment.yaml'


def test_each_hashed_input_invalidates_the_cache(cylinder, capsys):
    geometry, segment_path = cylinder
    out_dir = segment_path.parent
    first = _run(capsys, geometry, '--output-dir', out_dir, *MESH)
    assert 'condensed P1' in first
    base = load_segment(segment_path)
    assert base.metadata['inputs_sha256'] == _independent_sha(geometry, 1, 0.006)
    assert 'cached' in _run(capsys, geometry, '--output-dir', out_dir, *MESH)

    # the geometry file: double E in it -> recomputed, and C halves
    spec = yaml.safe_load(geometry.read_text())
    spec['material']['youngs_modulus'] *= 2.0
    geometry.write_text(yaml.safe_dump(spec))
    assert 'condensed P1' in _run(capsys, geometry, '--output-dir', out_dir, *MESH)
    stiffer = load_segment(segment_path)
    assert stiffer.metadata['inputs_sha256'] == _independent_sha(geometry, 1, 0.006)
    np.testing.assert_allclose(stiffer.compliance, 0.5 * base.compliance, rtol=1e-9,
                               atol=1e-12 * np.abs(base.compliance).max())

    # the mesh size and the element order
    assert 'condensed P1, mesh size 0.007' in _run(
        capsys, geometry, '--output-dir', out_dir, '--mesh-size', '0.007', '--order', '1')
    assert load_segment(segment_path).metadata['inputs_sha256'] == _independent_sha(
        geometry, 1, 0.007)
    assert 'condensed P2' in _run(capsys, geometry, '--output-dir', out_dir, '--mesh-size',
                                  '0.007', '--order', '2')
    assert load_segment(segment_path).metadata['inputs_sha256'] == _independent_sha(
        geometry, 2, 0.007)

    # a file made by another package version (its recorded sha differs): recomputed
    assert inputs_sha256(geometry, 2, 0.007, version='0.0.0') != inputs_sha256(
        geometry, 2, 0.007)
    data = yaml.safe_load(segment_path.read_text())
    data['inputs_sha256'] = _independent_sha(geometry, 2, 0.007, version='0.0.0')
    segment_path.write_text(yaml.safe_dump(data))
    assert 'condensed P2' in _run(capsys, geometry, '--output-dir', out_dir, '--mesh-size',
                                  '0.007', '--order', '2')
    # --force recomputes what is cached
    assert 'cached' in _run(capsys, geometry, '--output-dir', out_dir, '--mesh-size', '0.007',
                            '--order', '2')
    assert 'condensed P2' in _run(capsys, geometry, '--output-dir', out_dir, '--mesh-size',
                                  '0.007', '--order', '2', '--force')


def test_geo_material_and_length_enter_the_hash(tmp_path, capsys):
    geo = tmp_path / 'bar.geo'
    geo.write_text('SetFactory("OpenCASCADE");\nBox(1) = {0, -0.005, -0.005, 0.03, 0.01, 0.01};\n')
    common = [geo, '--output-dir', tmp_path, '--mesh-size', '0.005', '--order', '1',
              '--poisson-ratio', '0.3']
    assert 'condensed P1' in _run(capsys, *common, '--youngs-modulus', '1e6')
    soft = load_segment(tmp_path / 'bar.yaml')
    assert 'cached' in _run(capsys, *common, '--youngs-modulus', '1e6')
    assert 'condensed P1' in _run(capsys, *common, '--youngs-modulus', '2e6')
    stiff = load_segment(tmp_path / 'bar.yaml')
    np.testing.assert_allclose(stiff.compliance, 0.5 * soft.compliance, rtol=1e-9,
                               atol=1e-12 * np.abs(soft.compliance).max())
    assert 'condensed P1' in _run(capsys, *common, '--youngs-modulus', '2e6', '--density',
                                  '1000')
    assert load_segment(tmp_path / 'bar.yaml').mass == pytest.approx(1000.0 * 0.03 * 1e-4,
                                                                     rel=1e-6)
    assert 'condensed P1' in _run(capsys, *common, '--youngs-modulus', '2e6', '--density',
                                  '1000', '--segment-length', '0.031')


def test_bellows_segment_writes_its_cavities_and_needs_them_cached(tmp_path, capsys):
    """The CBHA bellows path: cavity surfaces beside the YAML; a missing one forces a rerun."""
    args = [meshes_path('cbha_segment_geometry.yaml'), '--output-dir', tmp_path,
            '--mesh-size', '0.004', '--order', '1']
    first = _run(capsys, *args)
    assert 'condensed P1' in first and first.count('cavity ') == 3
    segment = load_segment(tmp_path / 'cbha_segment.yaml')
    assert [c.name for c in segment.cavities] == ['over', 'right', 'left']
    for cavity in segment.cavities:
        assert cavity.triangles.shape[1] == 3 and cavity.points.shape[1] == 3
    assert 'cached' in _run(capsys, *args)
    (tmp_path / 'cbha_segment_cavity_left.vtk').unlink()
    assert 'condensed P1' in _run(capsys, *args)
    assert (tmp_path / 'cbha_segment_cavity_left.vtk').is_file()


def test_a_broken_geometry_exits_2_with_one_line_naming_file_and_key(tmp_path, capsys):
    broken = tmp_path / 'broken.yaml'
    broken.write_text('name: broken\nkind: cylinder\n')
    assert main([str(broken), '--output-dir', str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err == f'condense_segment: error: {broken}: mesh: missing\n'


def test_a_loaded_segment_is_kept_until_its_files_change(tmp_path):
    """load_segment reads a segment once per content of its YAML and its cavity files."""
    import shutil
    from cbha_inverse.paths import config_path
    for file in config_path('segments').glob('cbha_segment*'):
        shutil.copy(file, tmp_path / file.name)
    path = tmp_path / 'cbha_segment.yaml'
    first = load_segment(path)
    assert load_segment(path) is first
    assert not first.compliance.flags.writeable
    assert not first.cavities[0].points.flags.writeable
    with pytest.raises(ValueError):
        first.compliance[0, 0] = 1.0
    # the same bytes again (a new modification time): still the same segment
    path.write_bytes(path.read_bytes())
    assert load_segment(path) is first
    # a stiffer segment (the compliance halved), the same file size or not: read again
    data = yaml.safe_load(path.read_text())
    data['compliance'] = (0.5 * np.array(data['compliance'])).tolist()
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    stiffer = load_segment(path)
    np.testing.assert_allclose(stiffer.compliance, 0.5 * first.compliance, rtol=1e-15)
    # a changed cavity surface: read again, with the new points
    from cbha_inverse.fem.segment_io import read_cavity, write_cavity
    surface = tmp_path / data['cavities'][0]['file']
    points, triangles = read_cavity(surface)
    write_cavity(surface, 1.01 * points, triangles)
    moved = load_segment(path)
    assert moved is not stiffer
    np.testing.assert_allclose(moved.cavities[0].points, 1.01 * stiffer.cavities[0].points,
                               rtol=1e-12)
    np.testing.assert_array_equal(moved.cavities[1].points, stiffer.cavities[1].points)
