"""
``cbha_excite``: run an excitation program on the arm (real or simulated) while it is recorded.

Thin node around :mod:`cbha_inverse.identify.excitation`: publishes ``pressure_command``
(Float64MultiArray, gauge Pa in ``valve_names`` order, RELIABLE depth 10 as ``inverse_solver``)
at ``rate_hz``, the program's actuation at the time elapsed on the node clock since its first
command (``use_sim_time`` follows ``/clock``), and exits 0 once the program is done (the last
command, the end actuation, stays with the driver). Every command passes
:func:`cbha_inverse.robot.safety.check_command` (length, finite, ``[0, max_pressure]``) before
it is published. Progress is logged as ``hold i of n``.

It must not fight a controller: for ``discovery_time`` (steady clock) after its start it
looks for other publishers of ``pressure_command`` (e.g. ``inverse_solver``) and refuses to
start (error, exit 1) if there is one, unless ``force:=true``; one that appears later stops it
the same way. It then waits until ``wait_for_subscribers`` subscriptions (the driver or
``cbha_sim``, a bag recorder) match. SIGINT/SIGTERM before the end: exit 1, the last command
stays. Bad parameters or a bad program file: one line, exit 2. ``rate_hz``, ``discovery_time``
and ``wait_for_subscribers`` are live (``set_parameters``); the program is fixed at start.
"""

from dataclasses import dataclass
import sys
import time

from cbha_inverse.errors import ConfigError
from cbha_inverse.identify.excitation import DEFAULT_HOLD_TIME, DEFAULT_RAMP_TIME, make_program
from cbha_inverse.robot.robotino import ARM_VALVES
from cbha_inverse.robot.safety import check_command, command_bounds, valve_order
from cbha_inverse.ros.common.conversions import command_message
from cbha_inverse.ros.common.diagnostics import DiagnosticsPublisher, ERROR, make_status, OK
from cbha_inverse.ros.common.params import declare_parameters, param, ParameterError
from cbha_inverse.ros.common.qos import COMMAND_QOS
from cbha_inverse.ros.common.runner import run_node
from cbha_inverse.scene import load_scene
import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.task import Future
from std_msgs.msg import Float64MultiArray

NODE_NAME = 'cbha_excite'

REFUSED_EXIT = 1
"""Exit status when another publisher commands the valves, or the program was aborted."""

PHASES = ('discovery', 'waiting', 'ready', 'running', 'done', 'refused')

# the graph can list an endpoint before its node's name (the names DDS reports then)
UNKNOWN, UNKNOWN_NAMESPACE = '_NODE_NAME_UNKNOWN_', '_NODE_NAMESPACE_UNKNOWN_'
NAME_WAIT = 1.0
"""Longest wait [s] for the name of another publisher before refusing without it."""
END_ACK_TIMEOUT = 1.0
"""Longest wait [s] for the subscribers to acknowledge the end command before exiting."""


@dataclass(frozen=True)
class ExciteParams:
    """Parameters of the ``cbha_excite`` node."""

    scene: str = param('cbha.yaml', 'scene YAML: a file path, or a name in config/scenes')
    valve_names: tuple = param(None, 'command order: a permutation of the scene actuators '
                               '(unset: the scene order; the CBHA scene order is the vendor '
                               f'channels 0-5, {", ".join(ARM_VALVES)})',
                               unset_type='string_array')
    program: str = param('bends', 'excitation program: all, bends, extension, <section>_bends '
                         '(e.g. outer_bends), or a YAML file of holds (.yaml)')
    hold_time: float = param(DEFAULT_HOLD_TIME, 'duration of each hold [s]', low=0.01,
                             high=3600.0)
    ramp_time: float = param(DEFAULT_RAMP_TIME, 'duration of each linear ramp between '
                             'set-points [s]', low=0.01, high=3600.0)
    rate_hz: float = param(50.0, 'command rate [Hz]', low=1.0, high=1000.0, live=True)
    max_pressure: float = param(150000.0, 'driver limit [Pa]: the programs span the scene '
                                'bounds capped at it; every command is checked against it',
                                low=0.0, high=1.0e7)
    start_pressure: tuple = param(None, 'actuation at the start, valve_names order [Pa] '
                                  '(unset: mid range)', unset_type='double_array')
    end_pressure: tuple = param(None, 'actuation held after the end, valve_names order [Pa] '
                                '(unset: mid range)', unset_type='double_array')
    force: bool = param(False, 'start (and keep going) even though another node publishes '
                        'pressure_command')
    discovery_time: float = param(1.0, 'time to look for other publishers of pressure_command '
                                  'before the first command [s] (steady clock)', low=0.0,
                                  high=60.0, live=True)
    wait_for_subscribers: int = param(1, 'send nothing (and keep the program at t = 0) until '
                                      'this many subscriptions match pressure_command', low=0,
                                      high=1000, live=True)


def _display(publishers):
    """Name the publishers for a log line (one not yet identified as such)."""
    return [p.replace(f'{UNKNOWN_NAMESPACE}/{UNKNOWN}', 'an unidentified node')
            for p in publishers]


class ExciteNode(Node):
    """
    Publish an excitation program of pressure holds and ramps, then end.

    Parameters
    ----------
    **kwargs
        Passed to ``rclpy.node.Node`` (e.g. ``context``, ``namespace``, ``parameter_overrides``).

    Raises
    ------
    ParameterError
        If a parameter is invalid (the node is destroyed before raising).
    cbha_inverse.errors.ConfigError
        If the scene or the program file is invalid.

    Attributes
    ----------
    done : rclpy.task.Future
        Completes with the exit code: 0 when the program has been published to its end,
        :data:`REFUSED_EXIT` when another publisher was found or the clock ran backwards.
    program : cbha_inverse.identify.excitation.ExcitationProgram
        The program, scene actuator order.
    phase : str
        One of :data:`PHASES`.

    """

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        try:
            self.params = declare_parameters(self, ExciteParams, self._apply_parameters)
            p = self.params
            scene = load_scene(p.scene)
            self.valve_names, self.order = valve_order(scene.actuator_names, p.valve_names)
            lower, upper = command_bounds(scene.lower_bounds, scene.upper_bounds,
                                          p.max_pressure)
            self.program = make_program(
                scene, p.program, hold_time=p.hold_time, ramp_time=p.ramp_time,
                start=self._scene_order(p.start_pressure, 'start_pressure', lower, upper),
                end=self._scene_order(p.end_pressure, 'end_pressure', lower, upper),
                bounds=(lower, upper))
        except ConfigError:
            self.destroy_node()
            raise
        except (ValueError, FileNotFoundError) as exc:
            self.destroy_node()
            raise ParameterError(str(exc)) from None
        self.publisher = self.create_publisher(Float64MultiArray, 'pressure_command',
                                               COMMAND_QOS)
        self.done = Future()
        self.phase = 'discovery'
        self.published = 0
        self.elapsed = 0.0
        self.current_hold = -1
        self.reason = ''
        self._started = time.monotonic()
        self._t0 = None
        self._warned_force = False
        self._seen = None
        self.check_timer = self.create_timer(0.05, self._check,
                                             clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.timer = self.create_timer(1.0 / p.rate_hz, self._tick)
        self.diagnostics = DiagnosticsPublisher(self, self._statuses)
        self.get_logger().info(
            f'program {p.program}: {self.program.n_holds} holds of {p.hold_time:g} s, ramps '
            f'of {p.ramp_time:g} s, {self.program.duration:.1f} s at {p.rate_hz:g} Hz on '
            f'{self.publisher.topic_name} (valves {list(self.valve_names)}); looking for other '
            f'publishers for {p.discovery_time:g} s')

    def _apply_parameters(self, old, new):
        """Apply a change of the live parameters (checked by :func:`declare_parameters`)."""
        self.timer.timer_period_ns = int(round(1e9 / new.rate_hz))
        self.params = new

    def _scene_order(self, values, name, lower, upper):
        """Return a valve-order actuation parameter in scene order (None stays None)."""
        if values is None:
            return None
        values = np.asarray(values, dtype=float)
        if values.shape != self.order.shape:
            raise ValueError(f'parameter {name} needs {self.order.size} values (valve_names '
                             f'order), got {values.size}')
        for value, k, valve in zip(values, self.order, self.valve_names):
            if not lower[k] <= value <= upper[k]:
                raise ValueError(f'parameter {name}: {value:g} Pa for {valve} is outside '
                                 f'[{lower[k]:g}, {upper[k]:g}] Pa (scene bounds, max_pressure)')
        scene = np.empty_like(values)
        scene[self.order] = values
        return scene

    def other_publishers(self):
        """Return the names of the other nodes that publish on ``pressure_command``."""
        infos = self.get_publishers_info_by_topic(self.publisher.topic_name)
        me = (self.get_name(), self.get_namespace())
        others = [f'{i.node_namespace.rstrip("/")}/{i.node_name}' for i in infos
                  if (i.node_name, i.node_namespace) != me]
        if len(infos) - len(others) > 1:       # another node of the same name and namespace
            others.append(f'{me[1].rstrip("/")}/{me[0]} (a second one)')
        return others

    def _finish(self, code, reason=''):
        """End the node with exit ``code`` (once)."""
        if self.done.done():
            return
        self.phase = 'done' if code == 0 else 'refused'
        self.reason = reason
        self.timer.cancel()
        self.check_timer.cancel()
        self.done.set_result(code)

    def _check(self):
        """Steady-clock checks: other publishers, end of discovery, subscribers."""
        if self.done.done():
            return
        others = self.other_publishers()
        starting = self.phase in ('discovery', 'waiting', 'ready')
        if others and not self.params.force:
            now = time.monotonic()
            self._seen = now if self._seen is None else self._seen
            if starting and any(UNKNOWN in o for o in others) and now - self._seen < NAME_WAIT:
                self.phase = 'discovery'     # no start; the refusal waits for the names
                return
            others = _display(others)
            what = ('refusing to start' if starting
                    else f'stopping at t = {self.elapsed:.2f} s (the last command stays)')
            self.get_logger().error(
                f'{what}: {", ".join(others)} also publish(es) {self.publisher.topic_name}; '
                'stop that controller (e.g. inverse_solver) first, or set force:=true')
            self._finish(REFUSED_EXIT, f'other publishers: {", ".join(others)}')
            return
        if others and not self._warned_force:
            self._warned_force = True
            self.get_logger().warning(f'force: {", ".join(_display(others))} also publish(es) '
                                      f'{self.publisher.topic_name}')
        if self.phase == 'discovery' and (time.monotonic() - self._started
                                          >= self.params.discovery_time):
            self.phase = 'waiting'
        if self.phase == 'waiting' and (self.publisher.get_subscription_count()
                                        >= self.params.wait_for_subscribers):
            self.phase = 'ready'

    def _tick(self):
        """Publish the program's actuation at the current node-clock time."""
        now = self.get_clock().now()
        if self.phase == 'ready':
            if self.get_clock().ros_time_is_active and now.nanoseconds == 0:
                return                      # use_sim_time, no /clock yet
            self._t0 = now
            self.phase = 'running'
            self.get_logger().info(f'start: {self.program.duration:.1f} s')
        if self.phase != 'running':
            return
        elapsed = (now - self._t0).nanoseconds * 1e-9
        if elapsed < self.elapsed:
            self.get_logger().error(f'the clock went back from t = {self.elapsed:.3f} s to '
                                    f'{elapsed:.3f} s: stopping (the last command stays)')
            self._finish(REFUSED_EXIT, 'clock went backwards')
            return
        self.elapsed = elapsed
        finished = self.program.finished(elapsed)
        command = self.program.pressures_at(self.program.duration if finished else elapsed)
        command = command[self.order]
        check = check_command(command, len(self.valve_names), self.params.max_pressure)
        if not check.ok:      # the program lies within the bounds: this is a bug, never sent
            self.get_logger().error(f'command rejected by the safety check ({check.detail}): '
                                    'stopping')
            self._finish(REFUSED_EXIT, f'unsafe command: {check.detail}')
            return
        self.publisher.publish(command_message(command, self.valve_names))
        self.published += 1
        hold = self.program.hold_index(elapsed)
        if hold >= 0 and hold != self.current_hold:
            self.current_hold = hold
            kpa = ', '.join(f'{v * 1e-3:.0f}' for v in command)
            self.get_logger().info(f'hold {hold + 1} of {self.program.n_holds} '
                                   f'({self.program.labels[hold]}): [{kpa}] kPa')
        if finished:
            # the end command must reach the valves before the process exits (reliable QoS:
            # wait for the subscribers' acknowledgements, bounded)
            acked = self.publisher.wait_for_all_acked(Duration(seconds=END_ACK_TIMEOUT))
            self.get_logger().info(f'program done: {self.published} commands over '
                                   f'{elapsed:.2f} s; the end actuation stays'
                                   + ('' if acked else ' (the last command was not '
                                      f'acknowledged within {END_ACK_TIMEOUT:g} s)'))
            self._finish(0)

    def _statuses(self):
        level = ERROR if self.phase == 'refused' else OK
        hold = self.current_hold + 1
        return [make_status(self.get_name(), 'program', level, self.reason or self.phase, {
            'program': self.params.program, 'phase': self.phase,
            'hold': f'{hold} of {self.program.n_holds}', 'elapsed_s': self.elapsed,
            'duration_s': self.program.duration, 'published': self.published})]


def main(argv=None):
    """
    Run the ``cbha_excite`` node until its program is done.

    Parameters
    ----------
    argv : list of str, optional
        Command line (default ``sys.argv``), e.g. ``['cbha_excite', '--ros-args', '-r',
        '__ns:=/cbha', '-p', 'program:=outer_bends']``.

    Returns
    -------
    int
        0 when the program was published to its end, 1 when it refused to start, was
        stopped by another publisher or by SIGINT/SIGTERM, 2 on invalid parameters or a bad
        program file.

    """
    return run_node(ExciteNode, NODE_NAME, argv, params_class=ExciteParams)


if __name__ == '__main__':
    sys.exit(main())
