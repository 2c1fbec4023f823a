"""
The demo's square sent as one ``~/follow_trajectory`` goal: cross-track error over the whole run.

``python cbha_inverse/experiments/action_square.py [--mode closed] [--seconds 40]`` starts
``cbha_sim`` (the demo's plant: the CBHA scene, 10 % softer than the model), ``inverse_solver``
(closed loop by default) and ``trajectory --action`` (the paper's square: 80 mm at 3.1 cm/s in
the y-z plane around the scene's workspace centre, one lap) as processes in ``/cbha``, each
with its installed params file, records
``tip/true`` and ``pressure_command`` here, and prints the cross-track error of the plant's tip
from the first command to the goal's end, the start included: its distance to the planned path,
the straight approach from where the tip was at the first command to the square's start, then
the square (``docs/commanding.md``).
"""

import argparse
import os
import signal
import subprocess
import sys
import time

from cbha_inverse.paths import config_path
from cbha_inverse.robot.trajectory import square_vertices
import numpy as np

CENTER = (0.2308, 0.0, -0.0292)
"""The CBHA scene's workspace centre (the ``trajectory`` node's default) [m]."""


def polyline_distance(points, vertices):
    """
    Return the distance of each point to a polyline.

    Parameters
    ----------
    points : (n, 3) array_like  [m]
        The points.
    vertices : (v, 3) array_like  [m]
        The polyline, v >= 2.

    Returns
    -------
    (n,) ndarray  [m]

    """
    points = np.asarray(points, dtype=float)[:, None]
    start = np.asarray(vertices, dtype=float)[:-1][None]
    piece = np.diff(np.asarray(vertices, dtype=float), axis=0)[None]
    length2 = np.maximum(np.sum(piece ** 2, axis=2), 1e-300)
    fraction = np.clip(np.sum((points - start) * piece, axis=2) / length2, 0.0, 1.0)
    nearest = start + fraction[..., None] * piece
    return np.min(np.linalg.norm(points - nearest, axis=2), axis=1)


def main(argv=None):
    """Run the measurement; print one line; return 0 when the goal succeeded, else 1."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--mode', default='closed', choices=('open', 'closed'))
    parser.add_argument('--seconds', type=float, default=40.0, help='longest run [s]')
    args = parser.parse_args(argv)
    import rclpy
    from cbha_inverse.ros.common.qos import COMMAND_QOS, MEASURED_QOS
    from geometry_msgs.msg import PointStamped
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from std_msgs.msg import Float64MultiArray

    def ros(node):      # the installed params file, as cbha_launch starts a node
        return ['--ros-args', '-r', '__ns:=/cbha', '--params-file',
                str(config_path(f'{node}.yaml'))]

    arguments = {
        'cbha_sim': ros('cbha_sim'),
        'inverse_solver': [*ros('inverse_solver'), '-p', f'mode:={args.mode}'],
        'trajectory': ['--action', *ros('trajectory'), '-p', 'shape:=square', '-p', 'laps:=1',
                       '-p', 'speed:=0.031', '-p', 'side:=0.08', '-p', 'start_hold:=0.0']}
    context = rclpy.Context()
    rclpy.init(context=context)
    recorder = Node('action_square_recorder', context=context, namespace='/cbha')
    tips, first_command = [], []
    recorder.create_subscription(PointStamped, 'tip/true', lambda m: tips.append(
        (time.monotonic(), m.point.x, m.point.y, m.point.z)), MEASURED_QOS)
    recorder.create_subscription(Float64MultiArray, 'pressure_command', lambda m: first_command
                                 or first_command.append(time.monotonic()), COMMAND_QOS)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(recorder)
    processes = {}
    try:
        for name in ('cbha_sim', 'inverse_solver'):
            processes[name] = subprocess.Popen(
                [sys.executable, '-m', f'cbha_inverse.ros.nodes.{name}', *arguments[name]],
                env=os.environ, stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 120.0
        while not tips and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        time.sleep(3.0)     # the solver's warm-up and reachable sets
        processes['trajectory'] = subprocess.Popen(
            [sys.executable, '-m', 'cbha_inverse.ros.nodes.trajectory',
             *arguments['trajectory']], env=os.environ)
        deadline = time.monotonic() + args.seconds
        while processes['trajectory'].poll() is None and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        ended = time.monotonic()
        status = processes['trajectory'].poll()
    finally:
        for process in processes.values():
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        for process in processes.values():
            try:
                process.wait(timeout=15)
            except subprocess.TimeoutExpired:
                process.kill()
        executor.shutdown()
        recorder.destroy_node()
        rclpy.try_shutdown(context=context)
    if not first_command:
        print('no pressure_command: nothing ran')
        return 1
    samples = np.array(tips)
    at_start = samples[np.searchsorted(samples[:, 0], first_command[0]), 1:]
    path = np.vstack([at_start, square_vertices(CENTER, 0.08, 'yz')])
    window = samples[(samples[:, 0] >= first_command[0]) & (samples[:, 0] <= ended)]
    distance = polyline_distance(window[:, 1:], path)
    approach = np.linalg.norm(path[1] - path[0])
    print(f'{args.mode} loop, square as one goal (result {status}): {len(window)} tips over '
          f'{ended - first_command[0]:.1f} s, approach {1e3 * approach:.1f} mm; cross-track RMS '
          f'{1e3 * np.sqrt(np.mean(distance ** 2)):.3f} mm, max '
          f'{1e3 * distance.max():.3f} mm (first 2 s: max '
          f'{1e3 * distance[window[:, 0] < first_command[0] + 2.0].max():.3f} mm)')
    return 0 if status == 0 else 1


if __name__ == '__main__':
    sys.exit(main())
