"""
``stereo_calibrate``: checkerboard pairs -> two camera_info YAMLs and the rig; ``base_from_left``.

Calibrate: ``stereo_calibrate IMAGES --pattern 9x6 --square 0.03 --output DIR`` reads the pairs
``left_NNN.png`` / ``right_NNN.png`` of ``IMAGES``, calibrates (see
:mod:`cbha_inverse.vision.calibration`), prints the RMS reprojection error per camera and of the
pair and the baseline, and writes ``DIR/left.yaml``, ``DIR/right.yaml`` (camera_calibration_parsers
format) and ``DIR/rig.yaml`` (``base_from_left`` from ``--base-from-left``, default the default
rig's). ``--render N`` first renders N synthetic pairs of a known rig (``--truth``, default
``config/cameras/rig.yaml``) into ``IMAGES`` and prints the errors against it.

Register: ``stereo_calibrate --register POINTS.yaml --rig DIR/rig.yaml`` fits ``base_from_left``
(Kabsch) to >= 3 points tracked in the left camera frame (``stereo_tracker`` run with
``base_from_left: [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]``) whose ``cbha_base`` positions are known,
prints the pose and its residual and writes it into the rig file. ``POINTS.yaml``:
``points: [{left: [x, y, z], base: [x, y, z]}, ...]`` [m].

Exit codes: 0 done, 2 bad input (one line naming the file and the problem).
"""

import argparse
from pathlib import Path
import sys

from cbha_inverse.config_files import read_yaml
from cbha_inverse.errors import ConfigError, report_config_error
from cbha_inverse.paths import config_path
import numpy as np
import yaml


def parse_args(argv):
    """Parse the command line."""
    parser = argparse.ArgumentParser(prog='stereo_calibrate',
                                     description=__doc__.strip().split('\n\n')[0])
    parser.add_argument('images', nargs='?', help='folder of left_NNN.png / right_NNN.png pairs')
    parser.add_argument('--pattern', default='9x6',
                        help='inner corners per row x per column (OpenCV patternSize)')
    parser.add_argument('--square', type=float, default=0.03, help='square side [m]')
    parser.add_argument('--output', default='calibration', help='output folder')
    parser.add_argument('--base-from-left', type=float, nargs=7, default=None,
                        metavar=('X', 'Y', 'Z', 'QX', 'QY', 'QZ', 'QW'),
                        help='left camera pose in cbha_base to store (default: the default '
                        "rig's)")
    parser.add_argument('--render', type=int, default=0, metavar='N',
                        help='first render N synthetic pairs of --truth into IMAGES')
    parser.add_argument('--truth', default=None, help='rig rendered by --render (default: '
                        'config/cameras/rig.yaml)')
    parser.add_argument('--seed', type=int, default=0, help='seed of --render')
    parser.add_argument('--register', default=None, metavar='POINTS.yaml',
                        help='fit base_from_left to tracked points and write it into --rig')
    parser.add_argument('--rig', default=None, help='rig file updated by --register')
    return parser.parse_args(argv)


def _pattern(text):
    try:
        columns, rows = (int(v) for v in text.lower().split('x'))
    except ValueError:
        raise ValueError(f'--pattern must look like 9x6, got {text!r}') from None
    if columns < 2 or rows < 2:
        raise ValueError(f'--pattern needs at least 2x2 inner corners, got {text!r}')
    return columns, rows


def _register(args):
    from cbha_inverse.vision.rig import load_rig, register_base_from_left
    if args.rig is None:
        raise ValueError('--register needs --rig (the rig file to update)')
    path = Path(args.register)
    points = read_yaml(path).get('points')
    if not isinstance(points, list):
        raise ConfigError(path, 'points', 'missing: a list of {left: [x, y, z], base: [x, y, z]}')
    try:
        p_left = np.array([item['left'] for item in points], dtype=float)
        p_base = np.array([item['base'] for item in points], dtype=float)
        pose, rms = register_base_from_left(p_left, p_base)
    except (KeyError, TypeError, ValueError) as exc:
        raise ConfigError(path, 'points', f'{exc}') from None
    load_rig(args.rig)
    rig_path = Path(args.rig)
    rig_document = read_yaml(rig_path)
    rig_document['base_from_left'] = [round(float(v), 9) for v in pose]
    rig_path.write_text(yaml.safe_dump(rig_document, sort_keys=False, default_flow_style=None))
    print(f'base_from_left {[round(float(v), 6) for v in pose]} from {len(p_left)} points, '
          f'residual RMS {rms * 1e3:.3f} mm; written to {rig_path}')
    return 0


def _calibrate(args):
    from cbha_inverse.vision.calibration import (
        calibrate_stereo, read_pairs, render_calibration_pairs, write_pairs)
    from cbha_inverse.vision.rig import check_pose, load_rig, save_rig
    pattern = _pattern(args.pattern)
    if args.images is None:
        raise ValueError('give the folder of image pairs (or --register)')
    default_rig = load_rig(config_path('cameras', 'rig.yaml'))
    truth = load_rig(args.truth) if args.truth else default_rig
    if args.render:
        pairs = render_calibration_pairs(truth, args.render, pattern, args.square, args.seed)
        write_pairs(args.images, pairs)
        print(f'rendered {args.render} checkerboard pairs of {args.truth or "the default rig"} '
              f'into {args.images}')
    pose = check_pose(args.base_from_left if args.base_from_left is not None
                      else default_rig.base_from_left)
    result = calibrate_stereo(read_pairs(args.images), pattern, args.square, pose)
    rig = result.rig
    print(f'{result.pairs_used} pairs with the whole {pattern[0]}x{pattern[1]} pattern; RMS '
          f'reprojection error left {result.rms_left:.4f} px, right {result.rms_right:.4f} px, '
          f'stereo {result.rms_stereo:.4f} px; baseline {result.baseline * 1e3:.3f} mm')
    for name, camera in (('left', rig.left), ('right', rig.right)):
        k_matrix = camera.camera_matrix
        print(f'{name:5s}: fx {k_matrix[0, 0]:.2f} fy {k_matrix[1, 1]:.2f} cx '
              f'{k_matrix[0, 2]:.2f} cy {k_matrix[1, 2]:.2f} px, '
              f'D {np.round(camera.distortion, 5)}')
    if args.render:
        for name, estimated, true in (('left', rig.left, truth.left),
                                      ('right', rig.right, truth.right)):
            error = estimated.camera_matrix - true.camera_matrix
            print(f'{name:5s} vs truth: fx {100 * error[0, 0] / true.camera_matrix[0, 0]:+.3f} %,'
                  f' fy {100 * error[1, 1] / true.camera_matrix[1, 1]:+.3f} %, cx '
                  f'{error[0, 2]:+.2f} px, cy {error[1, 2]:+.2f} px')
        print(f'baseline vs truth: {(result.baseline - truth.baseline) * 1e3:+.3f} mm')
    path = save_rig(args.output, rig)
    print(f'wrote {Path(args.output) / "left.yaml"}, {Path(args.output) / "right.yaml"} and '
          f'{path}')
    return 0


def main(argv=None):
    """
    Run the command.

    Parameters
    ----------
    argv : list of str, optional
        Command line without the program name (default ``sys.argv[1:]``).

    Returns
    -------
    int
        0 when done, 2 on bad input (a one-line message on stderr).

    """
    args = parse_args(sys.argv[1:] if argv is None else argv)
    try:
        return _register(args) if args.register else _calibrate(args)
    except (ConfigError, ValueError, FileNotFoundError) as exc:
        return report_config_error('stereo_calibrate', exc)


if __name__ == '__main__':
    sys.exit(main())
