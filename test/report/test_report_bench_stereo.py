"""The cbha_bench_stereo console script on a few pairs: it tracks every pair, both ways."""

from cbha_inverse.report import bench_stereo


def test_bench_stereo_tracks_every_pair_with_and_without_the_window(capsys):
    """Both lines: every pair tracked within 0.3 mm RMS, the window used after the first pair."""
    assert bench_stereo.main(['--pairs', '30']) == 0
    lines = capsys.readouterr().out.splitlines()
    window = next(line for line in lines if line.startswith('window'))
    full = next(line for line in lines if line.startswith('full frame'))
    assert '30/30 tracked (29 in the window)' in window
    assert '30/30 tracked (0 in the window)' in full
    for line in (window, full):
        assert 'CPU median' in line
        assert float(line.split('RMS ')[1].split()[0]) < 0.3
