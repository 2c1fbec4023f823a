"""Tests of the block-tridiagonal solver against scipy.linalg.solveh_banded and dense solves."""

from cbha_inverse.core._kernels import block_band
from cbha_inverse.core._kernels.assembly import btd_cholesky
from cbha_inverse.core.linalg import btd
import numpy as np
import pytest
from scipy.linalg import solveh_banded

METHODS = ('compiled', 'dense', 'banded', 'auto')
BACKENDS = METHODS[:-1]


def _random_btd(rng, n, b=6, shift=None):
    """Return a random SPD block-tridiagonal matrix as blocks and as a dense array."""
    diag = rng.normal(size=(n, b, b))
    diag = diag @ np.swapaxes(diag, 1, 2)
    upper = rng.normal(size=(n - 1, b, b))
    dense = np.zeros((n * b, n * b))
    for i in range(n):
        dense[i * b:(i + 1) * b, i * b:(i + 1) * b] = diag[i]
    for i in range(n - 1):
        dense[i * b:(i + 1) * b, (i + 1) * b:(i + 2) * b] = upper[i]
        dense[(i + 1) * b:(i + 2) * b, i * b:(i + 1) * b] = upper[i].T
    # make it positive definite with a margin (Gershgorin-free: shift by the spectrum)
    low = np.linalg.eigvalsh(dense)[0]
    add = (1.0 - low) if shift is None else shift
    diag = diag + add * np.eye(b)
    dense = dense + add * np.eye(n * b)
    return diag, upper, dense


def _lower_band(dense, kd):
    """Lower band storage of a dense symmetric matrix, element by element (independent)."""
    size = dense.shape[0]
    ab = np.zeros((kd + 1, size))
    for j in range(size):
        for r in range(min(kd + 1, size - j)):
            ab[r, j] = dense[j + r, j]
    return ab


@pytest.mark.parametrize('n', [1, 2, 3, 6, 7, 16, 33])
@pytest.mark.parametrize('method', METHODS)
def test_matches_solveh_banded_and_dense(n, method):
    """All backends agree with solveh_banded and numpy's dense solve (1e-10, multi-RHS)."""
    rng = np.random.default_rng(100 + n)
    diag, upper, dense = _random_btd(rng, n)
    rhs = rng.normal(size=(6 * n, 20))
    ref_band = solveh_banded(_lower_band(dense, 11), rhs, lower=True)
    ref_dense = np.linalg.solve(dense, rhs)
    fac = btd.factorize(diag, upper, method=method)
    x = fac.solve(rhs)
    scale = np.abs(ref_dense).max()
    assert np.abs(x - ref_band).max() <= 1e-10 * scale
    assert np.abs(x - ref_dense).max() <= 1e-10 * scale
    # factor reuse: a second, single right-hand side with the same factor
    x1 = fac.solve(rhs[:, 3])
    assert x1.shape == (6 * n,)
    assert np.abs(x1 - ref_dense[:, 3]).max() <= 1e-10 * scale
    assert fac.method == (btd.choose_method(n) if method == 'auto' else method)


def test_band_storage_matches_definition():
    """to_lower_banded stores A[j + r, j] at [r, j] (LAPACK lower band, kd = 11)."""
    rng = np.random.default_rng(1)
    diag, upper, dense = _random_btd(rng, 5)
    ab = btd.to_lower_banded(diag, upper)
    np.testing.assert_array_equal(ab, _lower_band(dense, 11))
    assert ab.flags.f_contiguous


def test_auto_method_choice():
    """'auto' is the compiled backend at every size (it measured fastest everywhere)."""
    for n in (1, 6, 16, 100, 10 ** 6):
        assert btd.choose_method(n) == 'compiled'
    assert btd.factorize(*_random_btd(np.random.default_rng(5), 3)[:2]).method == 'compiled'


@pytest.mark.parametrize('method', METHODS)
def test_refuses_indefinite_matrix(method):
    """An indefinite matrix raises NotPositiveDefiniteError naming the block."""
    rng = np.random.default_rng(2)
    diag, upper, dense = _random_btd(rng, 12)
    diag[5] -= 1e3 * np.eye(6)
    with pytest.raises(btd.NotPositiveDefiniteError, match='not positive definite.*block 5'):
        btd.factorize(diag, upper, method=method)
    assert issubclass(btd.NotPositiveDefiniteError, np.linalg.LinAlgError)


@pytest.mark.parametrize('method', BACKENDS)
def test_condition_estimate(method):
    """The 1-norm condition estimate is a sharp lower bound and flags ill-conditioning."""
    rng = np.random.default_rng(3)
    diag, upper, dense = _random_btd(rng, 9)
    true = np.linalg.cond(dense, 1)
    est = btd.factorize(diag, upper, method=method).condition_estimate
    assert true / 3.0 <= est <= true * (1 + 1e-8)
    diag, upper, dense = _random_btd(rng, 9, shift=None)
    low = np.linalg.eigvalsh(dense)[0]
    diag = diag + (1e-11 - low) * np.eye(6)
    est = btd.factorize(diag, upper, method=method).condition_estimate
    assert est > 1e10
    with pytest.raises(btd.IllConditionedError, match='ill-conditioned'):
        btd.factorize(diag, upper, method=method, max_condition=1e8)


def test_bad_input():
    """Shape errors, unknown methods and non-finite entries are reported."""
    rng = np.random.default_rng(4)
    diag, upper, _ = _random_btd(rng, 4)
    with pytest.raises(ValueError):
        btd.factorize(diag, upper[:2])
    with pytest.raises(ValueError):
        btd.factorize(diag, upper, method='magic')
    bad = diag.copy()
    bad[2, 1, 1] = np.nan
    for method in BACKENDS:
        with pytest.raises((ValueError, np.linalg.LinAlgError)):
            btd.factorize(bad, upper, method=method)
    with pytest.raises(ValueError):
        btd.factorize(diag, upper).solve(np.ones(5))


@pytest.mark.parametrize('n', [1, 2, 6, 16, 100])
@pytest.mark.parametrize('k', [1, 6, 20])
def test_compiled_matches_solveh_banded_and_dense(n, k):
    """The compiled backend agrees with solveh_banded and a dense solve to 1e-10 (1-D and 2-D)."""
    rng = np.random.default_rng(200 + 7 * n + k)
    diag, upper, dense = _random_btd(rng, n)
    rhs = rng.normal(size=(6 * n, k))
    ref_band = solveh_banded(_lower_band(dense, 11), rhs, lower=True)
    ref_dense = np.linalg.solve(dense, rhs)
    scale = np.abs(ref_dense).max()
    fac = btd.factorize(diag, upper, method='compiled')
    assert fac.method == 'compiled'
    # a Fortran-ordered right-hand side (as from LAPACK) and the input left untouched
    rhs_f = np.asfortranarray(rhs)
    x = fac.solve(rhs_f)
    np.testing.assert_array_equal(rhs_f, rhs)
    assert x.shape == (6 * n, k)
    assert np.abs(x - ref_band).max() <= 1e-10 * scale
    assert np.abs(x - ref_dense).max() <= 1e-10 * scale
    x1 = fac.solve(rhs[:, -1])
    assert x1.shape == (6 * n,)
    assert np.abs(x1 - ref_dense[:, -1]).max() <= 1e-10 * scale


def test_compiled_accepts_strided_and_read_only_blocks():
    """Non-contiguous or read-only blocks are copied for the kernel (same result, no recompile)."""
    rng = np.random.default_rng(6)
    diag, upper, dense = _random_btd(rng, 7)
    rhs = rng.normal(size=(42, 3))
    ref = np.linalg.solve(dense, rhs)
    diag_t = np.swapaxes(np.swapaxes(diag, 1, 2).copy(), 1, 2)     # same values, not C order
    upper_ro = upper.copy()
    upper_ro.flags.writeable = False
    btd.factorize(diag, upper, method='compiled').solve(rhs)      # the C-ordered signature
    compiled = (list(btd_cholesky.signatures), list(block_band.block_solve.signatures))
    x = btd.factorize(diag_t, upper_ro, method='compiled').solve(np.asfortranarray(rhs))
    assert np.abs(x - ref).max() <= 1e-10 * np.abs(ref).max()
    # the C-ordered writable float64 signatures serve such inputs: no new compile (other tests
    # of this process may have compiled other layouts of the kernels directly)
    assert (list(btd_cholesky.signatures), list(block_band.block_solve.signatures)) == compiled


@pytest.mark.parametrize('block', [0, 5, 11])
def test_compiled_refuses_indefinite_matrix(block):
    """An indefinite matrix is refused by the compiled backend with the failing block named."""
    rng = np.random.default_rng(7)
    diag, upper, dense = _random_btd(rng, 12)
    diag[block] -= 1e3 * np.eye(6)
    with pytest.raises(btd.NotPositiveDefiniteError,
                       match=rf'compiled block Cholesky pivot .* \(block {block}, component'):
        btd.factorize(diag, upper, method='compiled')


def test_compiled_condition_estimate():
    """The compiled backend's condition estimate is within a factor 3 of np.linalg.cond(A, 1)."""
    rng = np.random.default_rng(8)
    for n, smallest in ((1, 1.0), (6, 1.0), (16, 1e-6), (40, 1.0)):
        diag, upper, dense = _random_btd(rng, n)
        shift = smallest - np.linalg.eigvalsh(dense)[0]      # smallest eigenvalue -> smallest
        diag = diag + shift * np.eye(6)
        true = np.linalg.cond(dense + shift * np.eye(6 * n), 1)
        est = btd.factorize(diag, upper, method='compiled').condition_estimate
        assert true / 3.0 <= est <= true * (1 + 1e-8)


@pytest.mark.parametrize('n', [1, 2, 9])
def test_btd_cholesky_writes_the_block_band_and_gives_numpys_factor(n):
    """
    btd_cholesky: block ``c`` of the band holds ``D_c`` and ``U_cᵀ``, factored in place.

    Its factor (1 / L_ii on the diagonal of the diagonal blocks) is numpy's Cholesky factor of
    the dense matrix; an indefinite diagonal block stops it at ``6 c + j + 1``, the first
    unknown whose pivot is not positive (the Schur complement of the leading minor).
    """
    rng = np.random.default_rng(20 + n)
    diag, upper, dense = _random_btd(rng, n)
    factor, info = btd_cholesky(diag, upper)
    assert info == 0 and factor.shape == (n, 2, 6, 6)
    lower = np.zeros((6 * n, 6 * n))
    for c in range(n):
        block = np.tril(factor[c, 0], -1) + np.diag(1.0 / np.diag(factor[c, 0]))
        lower[6 * c:6 * c + 6, 6 * c:6 * c + 6] = block
        if c + 1 < n:
            lower[6 * c + 6:6 * c + 12, 6 * c:6 * c + 6] = factor[c, 1]
    expected = np.linalg.cholesky(dense)
    np.testing.assert_allclose(lower, expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    bad = diag.copy()
    bad[n - 1] -= 1e3 * np.eye(6)
    dense[-6:, -6:] -= 1e3 * np.eye(6)
    pivots = [dense[p, p] - dense[p, :p] @ np.linalg.solve(dense[:p, :p], dense[:p, p])
              if p else dense[0, 0] for p in range(6 * n)]
    first = next(p for p, pivot in enumerate(pivots) if pivot <= 0.0)
    assert first // 6 == n - 1
    factor, info = btd_cholesky(bad, upper)
    assert info == first + 1
    assert factor[n - 1, 0, first % 6, first % 6] == pytest.approx(pivots[first], rel=1e-9)


def test_compiled_backend_takes_frame_blocks_only():
    """The compiled block Cholesky factors 6 x 6 blocks: other sizes are refused, not guessed."""
    rng = np.random.default_rng(9)
    diag, upper, _ = _random_btd(rng, 4, b=3)
    with pytest.raises(ValueError, match='6 x 6 blocks'):
        btd.factorize(diag, upper, method='compiled')
    assert btd.factorize(diag, upper).method == 'banded'
