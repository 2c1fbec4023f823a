"""A ``beam_vertebrae`` chain of sections: spacing, backbone and masses per part."""

from cbha_inverse.config_files import ConfigError, read_yaml
from cbha_inverse.core.statics import solve_static
from cbha_inverse.paths import config_path
from cbha_inverse.scene import load_scene
import numpy as np
import pytest
import yaml

TENDON_SCENE = config_path('scenes', 'tendon_6f_8c.yaml')


def _write(directory, chain, name='sections'):
    spec = read_yaml(TENDON_SCENE)
    spec.update(name=name, chain=chain)
    path = directory / f'{name}.yaml'
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return path


def _chain():
    return dict(read_yaml(TENDON_SCENE)['chain'])


def test_one_section_is_the_chain_itself(tmp_path):
    """The chain's keys moved into one section: the same model, frame for frame."""
    chain = _chain()
    part = {key: chain.pop(key) for key in ('n_vertebrae', 'interval_length', 'vertebra_mass')}
    sectioned = load_scene(_write(tmp_path, {**chain, 'sections': [part]}))
    plain = load_scene(TENDON_SCENE)
    np.testing.assert_array_equal(sectioned.model.masses, plain.model.masses)
    rest = sectioned.forward(np.zeros(8), strict=True).effector_positions
    np.testing.assert_array_equal(rest, plain.forward(np.zeros(8), strict=True)
                                  .effector_positions)


def test_a_stiffer_shorter_base_section_bends_as_the_cantilever_of_its_parts(tmp_path):
    """Two sections, gravity off, a tip force: the tip deflection of the stepped cantilever."""
    chain = _chain()
    backbone = chain.pop('backbone')
    stiff = {**backbone, 'youngs_modulus': 4.0 * backbone['youngs_modulus']}
    chain.pop('n_vertebrae'), chain.pop('interval_length')
    chain['sections'] = [{'n_vertebrae': 1, 'interval_length': 0.02, 'beams_per_interval': 4,
                          'backbone': stiff},
                         {'n_vertebrae': 2, 'interval_length': 0.04, 'backbone': backbone}]
    scene = load_scene(_write(tmp_path, chain), gravity=[0.0, 0.0, 0.0])
    frames = scene.model.n_frames
    assert frames == 1 + 4 + 2 * 2
    force = 1e-3
    res = solve_static(scene.model, tip_wrench=[0.0, 0.0, -force, 0.0, 0.0, 0.0], strict=True)
    # Euler-Bernoulli plus shear (Timoshenko) of a stepped cantilever under a tip force, by the
    # unit-load method: ∫ M m / EI dx + ∫ V v / (κ G A) dx over both parts
    radius, e, nu = backbone['outer_radius'], backbone['youngs_modulus'], backbone['poisson_ratio']
    inertia, area = np.pi * radius ** 4 / 4.0, np.pi * radius ** 2
    kappa = 6.0 * (1.0 + nu) / (7.0 + 6.0 * nu)
    x = np.linspace(0.0, 0.1, 200001)
    young = np.where(x < 0.02, 4.0 * e, e)
    shear = young / (2.0 * (1.0 + nu))
    integrand = (force * (0.1 - x) ** 2 / (young * inertia) + force / (kappa * shear * area))
    expected = np.sum((integrand[1:] + integrand[:-1]) / 2.0 * np.diff(x))
    deflection = -res.state.positions[-1, 2]
    assert deflection == pytest.approx(expected, rel=2e-3)
    # the stiff base carries half the compliance of a uniform rod: a model without it is far off
    assert abs(deflection / expected - 1.0) < 0.1 * abs(
        force * 0.1 ** 3 / (3.0 * e * inertia) / expected - 1.0)


@pytest.mark.parametrize('change, key, problem', [
    ({'sections': []}, 'chain.sections', 'needs at least one section'),
    ({'sections': [{'n_vertebrae': 3, 'interval_length': 0.04}], 'n_vertebrae': 3},
     'chain.n_vertebrae', 'give it per section'),
    ({'sections': [{'n_vertebrae': 3, 'interval_lenght': 0.04}]},
     'chain.sections[0].interval_lenght', "unknown key, did you mean 'interval_length'?"),
])
def test_a_wrong_section_is_one_line_naming_its_key(tmp_path, change, key, problem):
    chain = _chain()
    chain.pop('n_vertebrae'), chain.pop('interval_length')
    path = _write(tmp_path, {**chain, **change})
    with pytest.raises(ConfigError) as info:
        load_scene(path)
    assert info.value.key == key
    assert info.value.problem.startswith(problem), info.value.problem
