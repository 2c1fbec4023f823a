"""Condensation against Timoshenko, and chains of condensed segments against the full FE body."""

from cbha_inverse.core.links import checked_compliance, timoshenko_compliance
from cbha_inverse.fem.condensation import condense_cylinder
from cbha_inverse.fem.validation import large_bending, linear_chain_vs_full
import numpy as np
import pytest

E_MOD, NU = 1.0e6, 0.3


@pytest.fixture(scope='module')
def slender():
    """Condense a P2 cylinder with L / R = 10."""
    return condense_cylinder(0.1, 0.01, youngs_modulus=E_MOD, poisson_ratio=NU,
                             mesh_size=0.004)


def test_slender_cylinder_matches_timoshenko_within_two_percent(slender):
    ref = timoshenko_compliance(0.1, E_MOD, NU, 0.01)
    ratio = np.diag(slender.compliance) / np.diag(ref)
    print('slender L/R = 10, P2: C_fe / C_timoshenko diagonal =', np.round(ratio, 4))
    assert np.all(np.abs(ratio - 1.0) < 0.02)
    for i, j in [(1, 5), (2, 4)]:
        assert slender.compliance[i, j] / ref[i, j] == pytest.approx(1.0, abs=0.02)
    assert slender.asymmetry < 1e-10
    assert np.allclose(slender.rest_offset, [0.1, 0.0, 0.0])


def test_stubby_cylinder_is_reported_and_stiffer_than_beam_theory():
    stubby = condense_cylinder(0.02, 0.01, youngs_modulus=E_MOD, poisson_ratio=NU,
                               mesh_size=0.003)
    ratio = np.diag(stubby.compliance) / np.diag(timoshenko_compliance(0.02, E_MOD, NU, 0.01))
    print('stubby 20 mm x R10 mm, P2: C_fe / C_timoshenko diagonal =', np.round(ratio, 4))
    # rigid end faces stop the Poisson contraction and the warping: stiffer than the beam
    assert np.all(ratio[[0, 1, 2, 4, 5]] < 1.0)
    assert ratio[3] == pytest.approx(1.0, abs=0.01)


def test_p1_locks_in_bending(slender):
    p1 = condense_cylinder(0.1, 0.01, youngs_modulus=E_MOD, poisson_ratio=NU,
                           mesh_size=0.004, order=1)
    ratio = np.diag(p1.compliance) / np.diag(slender.compliance)
    print('P1 / P2 diagonal at the same mesh =', np.round(ratio, 4))
    assert ratio[4] < 0.97 and ratio[5] < 0.97


def test_symmetry_and_definiteness_checks_refuse_bad_matrices():
    good = timoshenko_compliance(0.05, E_MOD, NU, 0.01)
    sym, asym = checked_compliance(good)
    assert asym == 0.0 and np.array_equal(sym, good)
    skewed = good.copy()
    skewed[1, 5] *= 1.01
    # the asymmetry relative to sqrt(C_ii C_jj), computed independently
    expected = abs(skewed[1, 5] - skewed[5, 1]) / np.sqrt(skewed[1, 1] * skewed[5, 5])
    assert expected > 1e-3
    with pytest.raises(np.linalg.LinAlgError, match='asymmetric'):
        checked_compliance(skewed)
    slightly = good.copy()
    slightly[1, 5] *= 1.0 + 1e-10
    sym, asym = checked_compliance(slightly)
    assert asym == pytest.approx(abs(slightly[1, 5] - slightly[5, 1])
                                 / np.sqrt(slightly[1, 1] * slightly[5, 5]))
    np.testing.assert_array_equal(sym, sym.T)
    indefinite = good.copy()
    indefinite[4, 4] = -indefinite[4, 4]
    with pytest.raises(np.linalg.LinAlgError, match='positive definite'):
        checked_compliance(indefinite)


def test_chain_of_four_condensed_segments_matches_linear_full_fe():
    out = linear_chain_vs_full(4, 0.02, 0.005, youngs_modulus=E_MOD, poisson_ratio=NU,
                               mesh_size=0.0025)
    print('4 x 20 mm chain vs full FE, relative diagonal error:', np.round(out['error'], 6),
          f"full FE {out['full_seconds']:.3f} s, chain {out['chain_seconds'] * 1e3:.3f} ms")
    assert np.all(out['error'] < 0.005)


def test_large_bending_chain_vs_nonlinear_full_fe():
    out = large_bending()
    print(f"tip rotation {out['tip_rotation_deg']:.1f} deg, tip error "
          f"{100 * out['error_over_displacement']:.2f} % of the tip displacement "
          f"({100 * out['error_over_length']:.2f} % of the length); chain "
          f"{out['chain_seconds'] * 1e3:.1f} ms, full FE {out['full_seconds']:.2f} s")
    assert out['full'].converged and out['chain'].converged
    assert out['tip_rotation_deg'] >= 60.0
    assert out['error_over_displacement'] <= 0.02
