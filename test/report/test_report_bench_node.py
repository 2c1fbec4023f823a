"""The cbha_bench_node console script on a few targets: every target commanded, both runs."""

from cbha_inverse.report import bench_node
import numpy as np


def test_bench_node_commands_every_target_and_times_its_window(capsys):
    """Both runs: one window per target, its CPU time within its wall time."""
    assert bench_node.main(['--targets', '40', '--gap', '0.002']) == 0
    lines = capsys.readouterr().out.splitlines()
    runs = [line for line in lines if line.startswith(('back to back', '2 ms apart'))]
    assert len(runs) == 2
    for line in runs:
        assert line.endswith('| 40/40 commands')
        cpu, wall = (line.split(f'{what}: median ')[1].split(' ms')[0] for what in ('CPU', 'wall'))
        # a window's CPU time cannot exceed its wall time (one thread), and it is not zero
        assert 0.0 < float(cpu) <= float(wall) + 0.002


def test_time_windows_returns_one_window_per_published_command():
    """A target outside the workspace box is rejected: no command, no window."""
    import rclpy
    from rclpy.parameter import Parameter
    from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
    rclpy.init(args=[])
    try:
        node = InverseSolverNode(parameter_overrides=[Parameter('mode', value='open')])
        rest = node.solver.effector_positions()[0]
        targets = np.array([rest, rest + [0.0, 0.002, 0.0], [10.0, 0.0, 0.0], rest])
        published = node.published
        cpu, wall = bench_node.time_windows(node, targets, 0.0)
        assert cpu.shape == wall.shape == (3,)
        assert node.published - published == 3
        assert np.all(cpu <= wall + 1e-3)
        node.destroy_node()
    finally:
        rclpy.try_shutdown()
