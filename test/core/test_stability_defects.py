"""
Stiff and extreme cases of the static solver, each checked through the public API.

References are independent of the Newton engine: the linear flexibility of a serial chain
(wrench transported to each link, ``C_j`` applied, displacement carried to the tip), the
Timoshenko closed form of the whole beam, Euler's buckling load, and reachability.
"""

from dataclasses import replace
from pathlib import Path

from cbha_inverse.core.actuation.actuators import ActuatorSet
from cbha_inverse.core.actuation.cables import CableGroup
from cbha_inverse.core.chain import ChainModel
from cbha_inverse.core.inverse.solver import InverseSolver
from cbha_inverse.core.links import timoshenko_compliance
from cbha_inverse.core.statics import solve_static, StaticConvergenceError
from cbha_inverse.fem.condensation import condense_cylinder, condense_segment
from cbha_inverse.fem.segment_spec import MeshSettings, read_segment_spec
from cbha_inverse.scene import load_scene
import numpy as np
import pytest
import yaml

E_MOD, NU, RADIUS = 2.0e9, 0.3, 0.005
PACKAGE = Path(__file__).resolve().parents[2]


def _straight_chain(n_links, length, stiffness_factors=None):
    """Return (compliances (n, 6, 6), offsets (n, 3)) of a straight Timoshenko chain along x."""
    comp = np.broadcast_to(timoshenko_compliance(length / n_links, E_MOD, NU, RADIUS),
                           (n_links, 6, 6)).copy()
    if stiffness_factors is not None:
        comp /= np.asarray(stiffness_factors, dtype=float)[:, None, None]
    return comp, np.tile([length / n_links, 0.0, 0.0], (n_links, 1))


def _linear_tip_displacement(compliances, offsets, wrench):
    """
    Tip translation of a straight serial chain under a small tip wrench (linear flexibility).

    Link j carries the tip wrench transported to its end frame, ``(F, M + (p_tip - x_j+1) x F)``;
    its deformation ``C_j w_j`` moves the tip by ``d_t + d_r x (p_tip - x_j+1)``.
    """
    ends = np.cumsum(offsets, axis=0)
    tip = ends[-1]
    total = np.zeros(3)
    for comp, end in zip(compliances, ends):
        arm = tip - end
        local = np.concatenate([wrench[:3], wrench[3:] + np.cross(arm, wrench[:3])])
        deformation = comp @ local
        total += deformation[:3] + np.cross(deformation[3:], arm)
    return total


@pytest.mark.parametrize('factors', [
    [1.0] * 5 + [1e9] + [1.0] * 4,           # one near-rigid link (a rigid connector)
    [1.0] * 5 + [1e6] * 5,                   # adjacent stiffness ratio 1e6
    [1.0] * 9 + [1e9],                       # the rigid link carries the load
])
def test_stiff_links_deflect_like_the_linear_chain(factors):
    """A small tip load deflects the soft links: no 0-iteration 'equilibrium' at rest."""
    comp, offsets = _straight_chain(10, 0.1, factors)
    model = ChainModel.from_compliances(comp, offsets)
    wrench = np.array([0.0, 0.01, 0.0, 0.0, 0.0, 0.0])
    res = solve_static(model, tip_wrench=wrench)
    expected = _linear_tip_displacement(comp, offsets, wrench)
    assert res.converged and res.iterations >= 1
    np.testing.assert_allclose(res.positions[-1] - offsets.sum(axis=0), expected,
                               rtol=1e-4, atol=1e-4 * np.abs(expected).max())


def test_round_off_limited_residual_is_reported():
    """A 1e9 stiffness ratio cannot resolve the stiff link's forces: the result says so."""
    comp, offsets = _straight_chain(10, 0.1, [1.0] * 5 + [1e9] + [1.0] * 4)
    res = solve_static(ChainModel.from_compliances(comp, offsets),
                       tip_wrench=[0.0, 0.01, 0.0, 0.0, 0.0, 0.0])
    assert res.converged
    assert any('round-off' in text for text in res.warnings)
    soft = solve_static(ChainModel.from_compliances(*_straight_chain(10, 0.1)),
                        tip_wrench=[0.0, 0.01, 0.0, 0.0, 0.0, 0.0])
    assert soft.converged and soft.warnings == ()


def test_long_slender_chain_under_small_load_matches_timoshenko():
    """2000 links over 10 m, a 1 uN tip force: the whole-beam closed form (linear)."""
    n_links, length = 2000, 10.0
    comp, offsets = _straight_chain(n_links, length)
    model = ChainModel.from_compliances(comp, offsets)
    wrench = np.array([0.0, 1e-6, 0.0, 0.0, 0.0, 0.0])
    res = solve_static(model, tip_wrench=wrench)
    expected = (timoshenko_compliance(length, E_MOD, NU, RADIUS) @ wrench)[:3]
    assert res.converged and res.iterations >= 1
    np.testing.assert_allclose(res.positions[-1, 1], expected[1], rtol=1e-3)


@pytest.mark.parametrize('strict', [False, True])
@pytest.mark.parametrize('load', [
    {'tip_wrench': [0.0, np.inf, 0.0, 0.0, 0.0, 0.0]},
    {'tip_wrench': [np.nan, 0.0, 0.0, 0.0, 0.0, 0.0]},
    {'gravity': [0.0, 0.0, -np.inf]},
    {'frame_wrenches': np.full((4, 6), np.nan)},
])
def test_non_finite_loads_are_refused(load, strict):
    """Non-finite loads raise ValueError (never 'converged' with residual inf)."""
    model = ChainModel.from_compliances(*_straight_chain(4, 0.1), masses=np.full(4, 0.01))
    with pytest.raises(ValueError, match='finite'):
        solve_static(model, strict=strict, **load)


@pytest.mark.parametrize('field, value', [
    ('compliance', np.nan), ('compliance', np.inf), ('offset', np.inf), ('offset', np.nan),
    ('mass', np.nan), ('mass', np.inf),
])
def test_chain_model_refuses_non_finite_values(field, value):
    """ChainModel.from_compliances raises ValueError on NaN/inf, as its docstring says."""
    comp, offsets = _straight_chain(4, 0.1)
    masses = np.full(4, 0.01)
    if field == 'compliance':
        comp[2, 1, 1] = value
    elif field == 'offset':
        offsets[1, 0] = value
    else:
        masses[3] = value
    with pytest.raises(ValueError, match='finite'):
        ChainModel.from_compliances(comp, offsets, masses=masses)


def test_compression_past_buckling_is_flagged_unstable():
    """Euler: P_cr = pi^2 EI / (4 L^2); straight shape above it is returned with a warning."""
    n_links, length = 10, 0.2
    comp, offsets = _straight_chain(n_links, length)
    model = ChainModel.from_compliances(comp, offsets)
    bending = length / comp[:, 5, 5].sum()            # EI from the links' rotational compliance
    critical = np.pi ** 2 * bending / (4.0 * length ** 2)
    below = solve_static(model, tip_wrench=[-0.8 * critical, 0.0, 0.0, 0.0, 0.0, 0.0])
    above = solve_static(model, tip_wrench=[-1.3 * critical, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert below.converged and below.warnings == ()
    assert above.converged and np.allclose(above.positions[:, 1:], 0.0)
    assert any('unstable' in text for text in above.warnings)


def test_strain_beyond_small_strain_range_is_flagged():
    """A tension stretching the links by 20 % is solved and flagged (limit 10 %)."""
    comp, offsets = _straight_chain(4, 0.1)
    axial = 0.2 / (comp[0, 0, 0] / offsets[0, 0])     # force giving 20 % axial strain
    res = solve_static(ChainModel.from_compliances(comp, offsets),
                       tip_wrench=[axial, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert res.converged
    assert res.positions[-1, 0] == pytest.approx(0.12, rel=1e-6)
    assert any('strained' in text for text in res.warnings)


def test_strict_solve_raises_when_not_converged():
    """strict=True never returns an unconverged result."""
    comp, offsets = _straight_chain(10, 0.1)
    with pytest.raises(StaticConvergenceError):
        solve_static(ChainModel.from_compliances(comp, offsets),
                     tip_wrench=[0.0, 5e3, 0.0, 0.0, 0.0, 0.0], max_iterations=1,
                     max_load_steps=2, strict=True)


@pytest.fixture(scope='module')
def tendon_scene():
    """Load the paper's 6-frame, 8-tendon trunk."""
    return load_scene('tendon_6f_8c')


def test_huge_target_saturates_and_the_next_target_is_tracked(tendon_scene):
    """1e308 on each axis: finite actuation within bounds; a sane target afterwards is reached."""
    solver = tendon_scene.make_inverse_solver()
    for _ in range(3):
        out = solver.step([[1e308, 1e308, 1e308]])
        assert np.all(np.isfinite(out.actuation))
        assert np.all(out.actuation >= solver.lower_bounds)
        assert np.all(out.actuation <= solver.upper_bounds)
        assert out.status == 'saturated' and out.warnings
    target = tendon_scene.forward(np.full(8, 2.0)).effector_positions
    for _ in range(30):
        out = solver.step(target)
    assert out.status == 'solved'
    assert np.linalg.norm(out.effector_positions - target) < 1e-6


def test_transposed_targets_are_refused():
    """A (3, k) array is not silently reinterpreted as (k, 3)."""
    scene = load_scene('tendon_10f_16c')
    solver = scene.make_inverse_solver()
    targets = scene.rest_effector_positions
    assert solver.step(targets).status in ('solved', 'saturated')
    with pytest.raises(ValueError, match=r'\(2, 3\)'):
        solver.step(targets.T)
    with pytest.raises(ValueError, match=r'\(2, 3\)'):
        solver.step(targets.reshape(-1))


def test_zero_range_actuator_is_fixed_at_its_bound(tendon_scene):
    """A cable of zero range: the solver starts, names it, keeps it at 0, drives the rest."""
    scene = tendon_scene
    cables = list(scene.actuators.groups[0].cables)
    cables[1] = replace(cables[1], max_tension=0.0)
    actuators = ActuatorSet([CableGroup(cables, scene.model.n_frames)], scene.model.n_frames)
    solver = InverseSolver(scene.model, actuators, scene.effectors, gravity=scene.gravity)
    solver.warm_up()
    assert any('tip_90' in text and 'zero range' in text for text in solver.warnings)
    target = scene.forward(np.array([3.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 2.0])).effector_positions
    for _ in range(30):
        out = solver.step(target)
    assert np.all(np.isfinite(out.actuation)) and out.actuation[1] == 0.0
    assert np.linalg.norm(out.effector_positions - target) < 1e-6


def test_explicit_zero_poisson_ratio_is_honoured():
    """condense_segment(spec, poisson_ratio=0.0) uses 0.0, not the YAML's 0.3."""
    spec = replace(read_segment_spec(PACKAGE / 'meshes' / 'cylinder_segment.yaml'),
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


@pytest.mark.parametrize('args', [
    (np.nan, 1e9, 0.3, 0.01), (0.1, np.inf, 0.3, 0.01), (0.1, 1e9, np.nan, 0.01),
    (0.1, 1e9, 0.3, np.inf),
])
def test_timoshenko_compliance_refuses_non_finite_arguments(args):
    """A NaN length or an infinite modulus used to give a NaN or zero compliance."""
    with pytest.raises(ValueError, match='finite'):
        timoshenko_compliance(*args)


def test_condensation_refuses_a_non_finite_modulus():
    """A NaN Young's modulus used to fail deep in the sparse factorization."""
    with pytest.raises(ValueError, match='finite'):
        condense_cylinder(0.02, 0.01, youngs_modulus=np.nan, poisson_ratio=0.3,
                          mesh_size=0.006, order=1)


def test_condense_segment_command_prints_the_locking_warning(tmp_path, capsys):
    """The console script tells the user, not only the returned object."""
    from cbha_inverse.fem.cli import main as condense_main
    spec = yaml.safe_load((PACKAGE / 'meshes' / 'cylinder_segment.yaml').read_text(
        encoding='utf-8'))
    spec['material']['poisson_ratio'] = 0.49
    spec['mesh'] = {'order': 1, 'mesh_size': 0.006}
    geometry = tmp_path / 'locked.yaml'
    geometry.write_text(yaml.safe_dump(spec), encoding='utf-8')
    assert condense_main([str(geometry), '--output', str(tmp_path / 'segment.yaml')]) == 0
    assert 'warning: P1 tetrahedra lock at nu = 0.49' in capsys.readouterr().out
