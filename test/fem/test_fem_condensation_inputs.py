"""
The condensation's material inputs: an explicit Poisson ratio, P1 locking, a non-finite modulus.

``poisson_ratio=0.0`` given to :func:`~cbha_inverse.fem.condensation.condense_segment` is used
(not the YAML's value); P1 tetrahedra near incompressibility warn, in the returned segment and
in the ``condense_segment`` command's output; a NaN modulus is refused up front.
"""

from dataclasses import replace
from pathlib import Path

from cbha_inverse.fem.condensation import condense_cylinder, condense_segment
from cbha_inverse.fem.segment_spec import MeshSettings, read_segment_spec
import numpy as np
import pytest
import yaml

CYLINDER_YAML = Path(__file__).resolve().parents[1] / 'data' / 'cylinder_segment_geometry.yaml'


def test_explicit_zero_poisson_ratio_is_honoured():
    """condense_segment(spec, poisson_ratio=0.0) uses 0.0, not the YAML's 0.3."""
    spec = replace(read_segment_spec(CYLINDER_YAML),
                   mesh=MeshSettings(mesh_size=0.006, order=1))
    zero = condense_segment(spec, poisson_ratio=0.0)
    geom = spec.geometry
    direct = condense_cylinder(geom.length, geom.outer_radius, youngs_modulus=1.0e6,
                               poisson_ratio=0.0, mesh_size=0.006, order=1)
    yaml_nu = condense_segment(spec)
    np.testing.assert_allclose(zero.compliance, direct.compliance, rtol=1e-9)
    # torsion ~ (1 + nu): the YAML's nu = 0.3 gives a visibly larger torsion compliance
    assert yaml_nu.compliance[3, 3] > 1.1 * zero.compliance[3, 3]


def test_near_incompressible_p1_warns():
    """P1 at nu = 0.49 locks: the segment says so; at nu = 0.4 it does not."""
    common = {'youngs_modulus': 1.0e6, 'mesh_size': 0.006, 'order': 1}
    locked = condense_cylinder(0.02, 0.01, poisson_ratio=0.49, **common)
    fine = condense_cylinder(0.02, 0.01, poisson_ratio=0.4, **common)
    assert any('lock' in text for text in locked.warnings)
    assert fine.warnings == ()


def test_condensation_refuses_a_non_finite_modulus():
    """A NaN Young's modulus is refused before it reaches the sparse factorization."""
    with pytest.raises(ValueError, match='finite'):
        condense_cylinder(0.02, 0.01, youngs_modulus=np.nan, poisson_ratio=0.3,
                          mesh_size=0.006, order=1)


def test_condense_segment_command_prints_the_locking_warning(tmp_path, capsys):
    """The console script tells the user, not only the returned object."""
    from cbha_inverse.fem.cli import main as condense_main
    spec = yaml.safe_load(CYLINDER_YAML.read_text(encoding='utf-8'))
    spec['material']['poisson_ratio'] = 0.49
    spec['mesh'] = {'order': 1, 'mesh_size': 0.006}
    geometry = tmp_path / 'locked.yaml'
    geometry.write_text(yaml.safe_dump(spec), encoding='utf-8')
    assert condense_main([str(geometry), '--output', str(tmp_path / 'segment.yaml')]) == 0
    assert 'warning: P1 tetrahedra lock at nu = 0.49' in capsys.readouterr().out
