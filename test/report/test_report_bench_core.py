"""Smoke test of the cbha_bench_core console script on a tiny configuration."""

from cbha_inverse.report import bench_core


def test_bench_core_runs(capsys):
    """The benchmark prints the BTD table and the static-solve table and returns 0."""
    assert bench_core.main(['--sizes', '6', '--rhs', '6', '--budget', '0.0005']) == 0
    text = capsys.readouterr().out
    assert 'LAPACK pb' in text and 'ratio' in text
    assert 'Static solves, 17-frame chain' in text
    assert 'NOT CONVERGED' not in text
