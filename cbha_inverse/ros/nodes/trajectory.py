"""
``trajectory``: publish tip targets (PointStamped) along a circle, a square or a polyline.

Thin node around :mod:`cbha_inverse.robot.trajectory`. Topic ``target`` (relative: run it in the
``/cbha`` namespace with ``--ros-args -r __ns:=/cbha``), RELIABLE depth 10, frame ``frame_id``
(default ``cbha_base``), one message per timer tick at ``rate_hz``. Time runs on the node clock
(so ``use_sim_time`` follows ``/clock``) from the first tick. Bad parameters stop the node at start
with a message that names the parameter and a non-zero exit code. ``rate_hz`` and
``wait_for_subscribers`` are live (``set_parameters``); the path is fixed at start.

``action: true`` (or ``trajectory --action``) sends the whole path instead as one goal of
``action_server`` (control_msgs/FollowJointTrajectory, :meth:`cbha_inverse.robot.trajectory.
Trajectory.waypoints` of the effector ``effector``; ``docs/commanding.md``) once the server is
there, logs its feedback every second and ends with its result: exit 0 when it succeeded, 1
otherwise. The path needs an end then (``laps`` > 0 for a closed one).
"""

from dataclasses import dataclass
import sys

from cbha_inverse.robot.trajectory import make_trajectory, PLANES, SHAPES
from cbha_inverse.ros.common.conversions import point_stamped
from cbha_inverse.ros.common.diagnostics import DiagnosticsPublisher, make_status, OK
from cbha_inverse.ros.common.loading import split_ros_arguments
from cbha_inverse.ros.common.params import declare_parameters, param, ParameterError
from cbha_inverse.ros.common.qos import TARGET_QOS
from cbha_inverse.ros.common.runner import run_node
from geometry_msgs.msg import PointStamped
from rclpy.node import Node
from rclpy.task import Future

NODE_NAME = 'trajectory'


@dataclass(frozen=True)
class TrajectoryParams:
    """Parameters of the ``trajectory`` node (defaults: the paper's circle, section V)."""

    shape: str = param('circle', 'path shape', choices=SHAPES)
    center: tuple = param((0.2308, 0.0, -0.0292),
                          'circle/square centre [m] in frame_id, 3 numbers (x, y, z); default: '
                          'the CBHA scene workspace centre (tip at mid pressure)')
    radius: float = param(0.06, 'circle radius [m] (paper: 0.06)', low=0.0, high=10.0)
    side: float = param(0.08, 'square side [m] (paper: 0.08)', low=0.0, high=10.0)
    plane: str = param('yz', 'plane of circle/square: first axis, second axis (paper: yz)',
                       choices=PLANES)
    speed: float = param(0.025, 'speed along the path [m/s] (paper: 0.025 circle, 0.031 '
                         'square)', low=0.0, high=10.0)
    waypoints: tuple = param((0.2308, 0.0, -0.0292, 0.2308, 0.03, -0.0292, 0.2308, 0.03, 0.0008),
                             'waypoints [m] as a flat list x0, y0, z0, x1, ... (shape waypoints)')
    loop: bool = param(False, 'waypoints: return to the first waypoint and repeat')
    laps: int = param(0, 'laps to run, then hold the end point (0 = forever)', low=0, high=100000)
    start_hold: float = param(0.0, 'time at the start point before moving [s]',
                              low=0.0, high=3600.0)
    rate_hz: float = param(100.0, 'publication rate [Hz]', low=0.1, high=2000.0, live=True)
    frame_id: str = param('cbha_base', 'frame_id of the published targets')
    wait_for_subscribers: int = param(0, 'publish nothing (and keep the clock at 0) until this '
                                      'many subscriptions match target', low=0, high=1000,
                                      live=True)
    action: bool = param(False, 'send the path as one FollowJointTrajectory goal of '
                         'action_server instead of publishing targets, then end')
    action_server: str = param('inverse_solver/follow_trajectory', 'the action (action: true)')
    effector: str = param('tip', 'the effector the goal moves (action: true)')
    max_chord_error: float = param(1e-5, "action: largest distance of the goal's chords from "
                                   'a circle [m]', low=1e-9, high=0.1)


class TrajectoryNode(Node):
    """
    Publish the targets of one trajectory at a fixed rate.

    Parameters
    ----------
    **kwargs
        Passed to ``rclpy.node.Node`` (e.g. ``context``, ``namespace``, ``parameter_overrides``).

    Raises
    ------
    ParameterError
        If a parameter is invalid (the node is destroyed before raising).

    """

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        try:
            self.params = declare_parameters(self, TrajectoryParams, self._apply_parameters)
            p = self.params
            self.trajectory = make_trajectory(
                p.shape, center=p.center, radius=p.radius, side=p.side, plane=p.plane,
                speed=p.speed, waypoints=p.waypoints, loop=p.loop, laps=p.laps,
                start_hold=p.start_hold)
            if self.params.action:
                self.waypoints = self.trajectory.waypoints(self.params.max_chord_error)
        except ValueError as exc:
            self.destroy_node()
            raise ParameterError(f'invalid parameters: {exc}') from None
        if self.params.action:
            self._start_action()
            return
        self.publisher = self.create_publisher(PointStamped, 'target', TARGET_QOS)
        self._start = None
        self.published = 0
        self.timer = self.create_timer(1.0 / self.params.rate_hz, self._tick)
        self.diagnostics = DiagnosticsPublisher(self, self._statuses)
        self.get_logger().info(
            f'{self.params.shape}: length {self.trajectory.length:.4f} m at '
            f'{self.trajectory.speed:.4f} m/s, lap {self.trajectory.lap_time:.2f} s, '
            f'{self.params.rate_hz:g} Hz on {self.publisher.topic_name} '
            f'(frame {self.params.frame_id})')

    def _start_action(self):
        """Send the path as one goal once its server is there; ``done`` gets the exit code."""
        from cbha_inverse.ros.nodes.trajectory_action import PathGoal
        self.done = Future()
        self.goal = PathGoal(self, self.params.action_server, self.params.effector,
                             *self.waypoints, self.params.frame_id, self.done)

    def _apply_parameters(self, old, new):
        """Apply a change of the live parameters (checked by :func:`declare_parameters`)."""
        if self.params.action:
            self.params = new
            return
        self.timer.timer_period_ns = int(round(1e9 / new.rate_hz))
        self.params = new

    def elapsed(self):
        """Return the time since the first tick [s] (node clock), 0 before it."""
        now = self.get_clock().now()
        if self._start is None:
            self._start = now
        return (now - self._start).nanoseconds * 1e-9

    def _tick(self):
        if self._start is None and (self.publisher.get_subscription_count()
                                    < self.params.wait_for_subscribers):
            return
        elapsed = self.elapsed()
        self.publisher.publish(point_stamped(self.trajectory.sample(elapsed)[0],
                                             self.get_clock().now().to_msg(),
                                             self.params.frame_id))
        self.published += 1

    def _statuses(self):
        elapsed = 0.0 if self._start is None else self.elapsed()
        done = self.trajectory.finished(elapsed)
        return [make_status(self.get_name(), 'path', OK, 'finished, holding end point' if done
                            else 'running', {'shape': self.params.shape,
                                             'published': self.published,
                                             'elapsed_s': elapsed})]


def main(argv=None):
    """
    Run the ``trajectory`` node until SIGINT/SIGTERM.

    Parameters
    ----------
    argv : list of str, optional
        Command line (default ``sys.argv``), e.g. ``['trajectory', '--ros-args',
        '--params-file', 'config/trajectory.yaml', '-r', '__ns:=/cbha']``.

    Returns
    -------
    int
        0 on a clean shutdown, 2 on invalid parameters.

    """
    argv = list(sys.argv if argv is None else argv)
    own, ros = split_ros_arguments(argv[1:])
    if '--action' in own:       # the shortcut of -p action:=true
        own.remove('--action')
        argv = [argv[0], *own, *(ros or ['--ros-args']), '-p', 'action:=true']
    return run_node(TrajectoryNode, NODE_NAME, argv, params_class=TrajectoryParams)


if __name__ == '__main__':
    sys.exit(main())
