"""``stereo_calibrate`` on rendered checkerboard pairs of the default rig, against the truth."""

from cbha_inverse.core.so3 import so3_exp
from cbha_inverse.paths import config_path
from cbha_inverse.vision.calibrate_cli import main
from cbha_inverse.vision.marker import MarkerParams
from cbha_inverse.vision.render import StereoRenderer
from cbha_inverse.vision.rig import load_rig, pose_vector
from cbha_inverse.vision.tracking import StereoTracker
import numpy as np
import pytest
import yaml


@pytest.fixture(scope='module')
def calibrated(tmp_path_factory):
    """Run ``stereo_calibrate --render 15`` once; return (true rig, estimated rig, output)."""
    work = tmp_path_factory.mktemp('calibration')
    code = main([str(work / 'images'), '--render', '15', '--pattern', '9x6', '--square', '0.03',
                 '--output', str(work / 'out')])
    assert code == 0
    return load_rig(config_path('cameras', 'rig.yaml')), load_rig(work / 'out' / 'rig.yaml'), work


def test_calibration_recovers_the_rendered_rig(calibrated, capsys):
    """fx, fy within 0.5 %, cx, cy within 2 px, baseline within 0.5 mm (15 pairs)."""
    truth, estimated, work = calibrated
    assert len(list((work / 'images').glob('left_*.png'))) == 15
    for true, found in ((truth.left, estimated.left), (truth.right, estimated.right)):
        k_true, k_found = true.camera_matrix, found.camera_matrix
        assert abs(k_found[0, 0] / k_true[0, 0] - 1.0) < 0.005
        assert abs(k_found[1, 1] / k_true[1, 1] - 1.0) < 0.005
        assert abs(k_found[0, 2] - k_true[0, 2]) < 2.0
        assert abs(k_found[1, 2] - k_true[1, 2]) < 2.0
    assert abs(estimated.baseline - truth.baseline) < 0.5e-3
    assert estimated.right.projection[0, 3] < 0.0


def test_estimated_calibration_triangulates_within_0_5_mm(calibrated):
    """Markers rendered by the true rig, tracked with the estimated one: RMS <= 0.5 mm."""
    truth, estimated, _ = calibrated
    renderer = StereoRenderer(truth, seed=21)
    tracker = StereoTracker(estimated, MarkerParams(window=0))
    rng = np.random.default_rng(8)
    errors = []
    for p_base in rng.uniform([0.15, -0.11, -0.14], [0.26, 0.11, 0.08], (100, 3)):
        result = tracker.track(*renderer.render(p_base))
        assert result.ok, result
        errors.append(np.linalg.norm(result.p_base - p_base))
    rms = float(np.sqrt(np.mean(np.square(errors))))
    print(f'\nestimated calibration: triangulation RMS {rms * 1e3:.4f} mm, max '
          f'{max(errors) * 1e3:.4f} mm')
    assert rms <= 0.5e-3


def test_register_writes_base_from_left(calibrated, tmp_path, capsys):
    """--register fits base_from_left to tracked points and writes it into the rig file."""
    _, estimated, work = calibrated
    truth = pose_vector(so3_exp([0.1, -2.0, 0.4]), [0.7, -0.1, 0.05])
    rotation = so3_exp([0.1, -2.0, 0.4])
    p_base = np.array([[0.2, 0.0, 0.0], [0.25, 0.05, -0.02], [0.18, -0.06, 0.04],
                       [0.22, 0.02, 0.06]])
    p_left = (p_base - truth[:3]) @ rotation
    points = tmp_path / 'points.yaml'
    points.write_text(yaml.safe_dump({'points': [
        {'left': a.tolist(), 'base': b.tolist()} for a, b in zip(p_left, p_base)]}))
    rig_file = work / 'out' / 'rig.yaml'
    assert main(['--register', str(points), '--rig', str(rig_file)]) == 0
    assert 'residual RMS 0.000 mm' in capsys.readouterr().out
    assert load_rig(rig_file).base_from_left == pytest.approx(truth, abs=1e-8)


@pytest.mark.parametrize('arguments, message', [
    (['{tmp}', '--pattern', '9by6'], '--pattern must look like 9x6'),
    (['{tmp}'], 'no left_*.png / right_*.png pairs'),
    (['--register', '{tmp}/absent.yaml', '--rig', '{tmp}/rig.yaml'], 'no such file'),
])
def test_bad_input_exits_2_with_one_line(tmp_path, capsys, arguments, message):
    """A bad pattern, an empty folder or a missing file: exit code 2 and one line on stderr."""
    assert main([a.format(tmp=tmp_path) for a in arguments]) == 2
    error = capsys.readouterr().err
    assert error.startswith('stereo_calibrate: error: '), error
    assert message in error and error.count('\n') == 1, error
