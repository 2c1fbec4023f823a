"""
Statics and the chain model on stiff, slender, non-finite and over-loaded cases.

The references are independent of the Newton engine: the linear flexibility of a serial chain
(wrench transported to each link, ``C_j`` applied, displacement carried to the tip), the
Timoshenko closed form of the whole beam and Euler's buckling load. Stiffness ratios up to 1e9,
2000 links, compression past buckling and 20 % strain are solved and flagged; NaN and inf are
refused where they enter (loads, the chain model, the link compliance).
"""

from cbha_inverse.core.chain import ChainModel
from cbha_inverse.core.links import timoshenko_compliance
from cbha_inverse.core.statics import solve_static, StaticConvergenceError
import numpy as np
import pytest

E_MOD, NU, RADIUS = 2.0e9, 0.3, 0.005


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


@pytest.mark.parametrize('args', [
    (np.nan, 1e9, 0.3, 0.01), (0.1, np.inf, 0.3, 0.01), (0.1, 1e9, np.nan, 0.01),
    (0.1, 1e9, 0.3, np.inf),
])
def test_timoshenko_compliance_refuses_non_finite_arguments(args):
    """A NaN length or an infinite modulus is refused, not turned into a NaN or zero compliance."""
    with pytest.raises(ValueError, match='finite'):
        timoshenko_compliance(*args)
