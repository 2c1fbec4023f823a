"""
``cbha_bench_node``: the CPU time of ``inverse_solver``'s target -> command window.

Builds the node in this process (real rclpy, the scene's solver, open loop, trigger
``target``), then hands it ``--targets`` targets along the paper's circle by calling its target
callback directly, so that no executor or other process is timed: the window is the node's own
``latency_cpu`` (the control thread's CPU time from the callback's entry to the command's
publication, ``docs/nodes.md``, "Latency"). Twice: back to back (the caches hot), and with
``--gap`` between targets (10 ms: the 100 Hz tick's idle time, after which the caches are
cold, as in a running loop). The command publisher has no subscriber here: a matched reader
adds the DDS send to each window.
"""

import argparse
import os
import sys
import time

import numpy as np

CIRCLE_RADIUS_M = 0.01
"""Radius of the target circle around the scene's rest tip [m]."""


def parse_args(argv):
    """Parse the command line."""
    parser = argparse.ArgumentParser(prog='cbha_bench_node',
                                     description=__doc__.strip().split('\n\n')[0])
    parser.add_argument('--scene', default='cbha', help='scene name or file')
    parser.add_argument('--targets', type=int, default=600, help='targets per run')
    parser.add_argument('--gap', type=float, default=0.01,
                        help='time between targets of the cold run [s]')
    return parser.parse_args(argv)


def time_windows(node, targets, gap):
    """
    Hand targets to the node's target callback and return its window times.

    Parameters
    ----------
    node : InverseSolverNode
        The node (not spinning).
    targets : (t, 3) ndarray  [m]
        Targets in the node's frame.
    gap : float  [s]
        Sleep before each target (0: back to back).

    Returns
    -------
    cpu, wall : (w,) ndarray  [s]
        The window's CPU time and wall time per published command (``w = t`` when every
        target was solved and published).

    """
    from geometry_msgs.msg import PointStamped
    message = PointStamped()
    message.header.frame_id = node.params.frame_id
    node.latency_cpu = type(node.latency_cpu)()
    node.latencies = type(node.latencies)()
    for point in targets:
        if gap > 0.0:
            time.sleep(gap)
        message.point.x, message.point.y, message.point.z = point.tolist()
        node._on_target(message)
    return (np.fromiter(node.latency_cpu._samples, dtype=float),
            np.fromiter(node.latencies._samples, dtype=float))


def summary(label, seconds):
    """Return one line: median, p90 and p99 [ms] of a (t,) array of seconds."""
    ms = 1e3 * seconds
    return (f'{label}: median {np.median(ms):.3f} ms, p90 {np.percentile(ms, 90):.3f} ms, '
            f'p99 {np.percentile(ms, 99):.3f} ms')


def main(argv=None):
    """
    Run the benchmark and print the window per run.

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
    import rclpy
    from rclpy.parameter import Parameter
    from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
    rclpy.init(args=[])
    try:
        node = InverseSolverNode(parameter_overrides=[
            Parameter('scene', value=args.scene), Parameter('mode', value='open')])
        rest = node.solver.effector_positions()[0]
        angles = np.linspace(0.0, 2.0 * np.pi, args.targets)
        targets = rest + CIRCLE_RADIUS_M * np.column_stack(
            [np.zeros_like(angles), np.cos(angles), np.sin(angles)])
        time_windows(node, targets[:50], 0.0)   # the first ticks from rest are not timed
        print(f'cbha_bench_node: inverse_solver, scene {node.scene.name}, {args.targets} '
              f'targets on a {1e3 * CIRCLE_RADIUS_M:g} mm circle, load average '
              f'{os.getloadavg()[0]:.1f}; target -> command window of the target callback')
        for label, gap in (('back to back', 0.0), (f'{1e3 * args.gap:g} ms apart', args.gap)):
            cpu, wall = time_windows(node, targets, gap)
            print(f'{label:14s} {summary("CPU", cpu)} | {summary("wall", wall)} | '
                  f'{cpu.size}/{len(targets)} commands')
        node.destroy_node()
    finally:
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
