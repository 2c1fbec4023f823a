"""
``cbha_bench_stereo``: stereo tracking time per image pair, window search against full frame.

Renders ``--pairs`` pairs of a rig (default: ``config/cameras/rig.yaml``, 1280x1024) along the
paper's circle (r = 60 mm in the y-z plane around the CBHA's workspace centre, as tracked frame
after frame), then times :meth:`cbha_inverse.vision.tracking.StereoTracker.track` (detection in
both images, rectification, triangulation, checks; rendering excluded) with the search window
(``marker.window`` 48 px) and with the full frame every time (window 0), and prints the median
and p99 per pair, the median CPU time of the process per pair (what the wall time becomes on a
machine busy with other work) and the triangulation error. The goals on an idle 2-core machine:
<= 0.5 ms median with the window, <= 5 ms on the full frame.
"""

import argparse
import sys
import time

from cbha_inverse.paths import config_path
from cbha_inverse.vision.marker import MarkerParams
from cbha_inverse.vision.render import StereoRenderer
from cbha_inverse.vision.rig import load_rig
from cbha_inverse.vision.tracking import StereoTracker
import numpy as np

CENTRE = np.array([0.2308, 0.0, -0.0292])
"""Workspace centre of config/scenes/cbha.yaml in cbha_base [m]."""


def parse_args(argv):
    """Parse the command line."""
    parser = argparse.ArgumentParser(prog='cbha_bench_stereo',
                                     description=__doc__.strip().split('\n\n')[0])
    parser.add_argument('--rig', default=None, help='rig file (default config/cameras/rig.yaml)')
    parser.add_argument('--pairs', type=int, default=300, help='image pairs per mode')
    parser.add_argument('--window', type=int, default=48, help='search window half size [px]')
    return parser.parse_args(argv)


def time_tracking(rig, pairs, truth, window):
    """
    Track every pair with one tracker and time each call.

    Parameters
    ----------
    rig : StereoRig
        The rig.
    pairs : sequence of (ndarray, ndarray)
        Image pairs in order.
    truth : (N, 3) ndarray  [m]
        True marker positions.
    window : int  [px]
        Search window half size (0: full frame).

    Returns
    -------
    times : (N,) ndarray  [s]
        Wall time per pair.
    cpu_times : (N,) ndarray  [s]
        CPU time of the process (all its threads) per pair.
    errors : (M,) ndarray  [m]
        Triangulation errors of the accepted pairs.
    windowed : int
        Pairs found inside the windows.

    """
    tracker = StereoTracker(rig, MarkerParams(window=window))
    times, cpu_times, errors, windowed = [], [], [], 0
    for (left, right), p_base in zip(pairs, truth):
        start, cpu_start = time.perf_counter(), time.process_time()
        result = tracker.track(left, right)
        times.append(time.perf_counter() - start)
        cpu_times.append(time.process_time() - cpu_start)
        if result.ok:
            errors.append(np.linalg.norm(result.p_base - p_base))
            windowed += result.windowed
    return np.array(times), np.array(cpu_times), np.array(errors), windowed


def main(argv=None):
    """
    Run the benchmark and print one line per mode.

    Parameters
    ----------
    argv : list of str, optional
        Command line without the program name (default ``sys.argv[1:]``).

    Returns
    -------
    int
        0.

    """
    args = parse_args(sys.argv[1:] if argv is None else argv)
    rig = load_rig(args.rig or config_path('cameras', 'rig.yaml'))
    renderer = StereoRenderer(rig, seed=0)
    angles = np.linspace(0.0, 2.0 * np.pi, args.pairs, endpoint=False)
    truth = CENTRE + 0.06 * np.column_stack([np.zeros_like(angles), np.cos(angles),
                                             np.sin(angles)])
    pairs = [renderer.render(p) for p in truth]
    print(f'cbha_bench_stereo: {args.pairs} rendered pairs {rig.left.width}x{rig.left.height} '
          f'bgr8, circle r = 60 mm; time of StereoTracker.track per pair (detection in both '
          f'images, rectification, triangulation, checks)')
    for label, window in (('window', args.window), ('full frame', 0)):
        times, cpu_times, errors, windowed = time_tracking(rig, pairs, truth, window)
        times_ms = times * 1e3
        rms = float(np.sqrt(np.mean(errors ** 2))) if errors.size else float('nan')
        print(f'{label:10s}: median {np.median(times_ms):6.2f} ms, p99 '
              f'{np.percentile(times_ms, 99):6.2f} ms, CPU median '
              f'{np.median(cpu_times) * 1e3:6.2f} ms | {errors.size}/{len(pairs)} tracked '
              f'({windowed} in the window), RMS {rms * 1e3:.3f} mm', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
