"""Smoke test of cbha_bench_estimator on a short lap."""

import json

from cbha_inverse.report import bench_estimator


def test_bench_estimator_runs(capsys, tmp_path):
    """The benchmark prints its two lines; the estimate beats the open-loop model."""
    out = tmp_path / 'row.json'
    assert bench_estimator.main(['--poses', '40', '--json', str(out)]) == 0
    text = capsys.readouterr().out
    assert 'estimator update median' in text and 'open-loop model RMS' in text
    row = json.loads(out.read_text())
    assert row['updates'] == 40 and row['degraded'] == 0
    assert row['rms'] < 0.5 * row['open_loop_rms']


def test_the_lap_sweeps_both_sections():
    lap = bench_estimator.pressure_lap(12)
    assert lap.shape == (12, 6)
    assert lap.min() >= 0.0 and lap.max() <= 1.5e5
    assert (lap[:, :3].argmax(axis=1) != lap[:, 3:].argmax(axis=1)).any()
