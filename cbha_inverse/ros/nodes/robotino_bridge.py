"""
``robotino_bridge``: our pressure command to the Robotino ROS 2 driver's CBHA messages and back.

On a real CBHA the valves are driven by the Robotino driver (``robotino_node``), which subscribes
``set_bha_pressures`` (``robotino_msgs/msg/SetBHAPressures``: exactly 8 set-points in bar, arm
channels 0-5 in the vendor order, wrist 6-7) and publishes ``bha_readings``
(``robotino_msgs/msg/BHAReadings``: stamp, pressures in bar, the six string potentiometers).

The bridge subscribes ``pressure_command`` (Float64MultiArray, gauge Pa in ``valve_names`` order,
reliable) and forwards each valid command at once to ``/set_bha_pressures`` through
:func:`cbha_inverse.robot.robotino.robotino_bar_command` (wrist channels from ``wrist_bar``, cap
``max_bar``). A command that is not finite, not of length ``len(valve_names)`` or outside
``[0, max_pressure]`` is never forwarded (:func:`cbha_inverse.robot.safety.check_command`; logged
with throttling and counted). When no valid command arrived within ``controller_loss_timeout``
(steady clock; a lost controller), the bridge publishes at ``rate_hz`` either the last forwarded
set-points (``on_controller_loss: hold``) or the vent set-points (``vent``: arm channels at
``vent_pressure``, wrist at 0: the driver has no vent of its own, a vented valve is a zero
set-point). ``command_timeout`` and ``stale_action`` are the old names of those two parameters,
still read (a value set under either name counts; both names set to different values is
refused). As the solver, it publishes nothing before the first valid command (another publisher
of ``/set_bha_pressures`` is not overridden), or the vent set-points at ``rate_hz`` with
``publish_idle: true``.

Services: ``~/vent`` and ``~/hold`` (std_srvs/Trigger) stop forwarding commands (they are
counted, not sent) and publish the vent set-points, or the last set-points, at ``rate_hz`` until
``~/enable true`` (std_srvs/SetBool; ``false`` vents, as ``~/vent``). When the bridge itself stops
(Ctrl-C, SIGTERM: its node is destroyed) after it sent set-points, ``on_exit: vent`` sends the
vent set-points first (acknowledged within :data:`EXIT_ACK_TIMEOUT`): its watchdog ends with it,
and the driver would hold the last set-points for ever; ``hold`` leaves them.

Each ``/bha_readings`` message is republished as ``pressure_measured`` (Float64MultiArray, Pa in
``valve_names`` order, :func:`cbha_inverse.robot.robotino.robotino_pressures`) and
``string_pots`` (sensor_msgs/JointState: the driver's stamp, one name per potentiometer, the raw
values as positions). ``/diagnostics`` reports the command and reading rates, the reading age,
the rejected commands and measured - commanded pressure per valve.

``robotino_msgs`` is imported when the node starts, not when this module is imported; when it is
missing the node stops with one line saying how to get it.
"""

from dataclasses import dataclass, fields
import importlib
import math
import sys
import time

from cbha_inverse.robot.robotino import (
    ARM_VALVES, CHANNELS, MAX_BAR, N_CHANNELS, PASCAL_PER_BAR, robotino_bar_command,
    robotino_pressures, string_pot_names)
from cbha_inverse.robot.safety import (
    ACTIONS, check_command, SilenceWarning, StalenessWatch, watchdog_action)
from cbha_inverse.ros.common.conversions import command_array, command_message, joint_state
from cbha_inverse.ros.common.diagnostics import (
    DiagnosticsPublisher, make_status, OK, RateMeter, WARN)
from cbha_inverse.ros.common.params import declare_parameters, param, ParameterError
from cbha_inverse.ros.common.qos import (
    COMMAND_QOS, DRIVER_READINGS_QOS, DRIVER_SET_POINTS_QOS, MEASURED_QOS)
from cbha_inverse.ros.common.rejections import Rejections, ThrottledLog
from cbha_inverse.ros.common.runner import run_node
import numpy as np
from rclpy.duration import Duration
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import SetBool, Trigger

NODE_NAME = 'robotino_bridge'

MISSING_MESSAGES = (
    'robotino_msgs is not importable ({error}): `make install` builds it into the venv; '
    "elsewhere, source the Robotino driver's workspace, or build this package's copy with "
    '`cbha_build_robotino_msgs --workspace WS` and source WS/install/setup.sh')
"""The one line printed when the driver's message package is missing."""

EXIT_ACK_TIMEOUT = 1.0
"""Longest wait [s] for the driver to acknowledge the vent set-points sent at exit."""

RENAMED = {'controller_loss_timeout': 'command_timeout', 'on_controller_loss': 'stale_action'}
"""Parameters still read under their old names (``name: old name``)."""

STRING_POTS = tuple(f'string_pot_{name}' for name in ARM_VALVES)
"""Default names of the six string potentiometers (one per arm bellows, channel order)."""


@dataclass(frozen=True)
class RobotinoBridgeParams:
    """Parameters of the ``robotino_bridge`` node."""

    valve_names: tuple = param(ARM_VALVES, 'order of pressure_command and pressure_measured: '
                               'valve names of the vendor channels (inner_over ... outer_left, '
                               'wrist_horizontal, wrist_vertical)')
    max_pressure: float = param(150000.0, 'largest forwarded command [Pa]: commands above are '
                                'rejected (at most 1.5 bar)', low=0.0,
                                high=MAX_BAR * PASCAL_PER_BAR, live=True)
    max_bar: float = param(MAX_BAR, 'cap of every set-point sent to the driver [bar]',
                           low=0.0, high=MAX_BAR)
    wrist_bar: tuple = param((0.0, 0.0), 'set-points of the wrist channels 6 and 7 [bar] when '
                             'valve_names does not command them')
    controller_loss_timeout: float = param(0.5, 'no valid pressure_command for this long is a '
                                           'lost controller [s] (steady clock)', low=0.001,
                                           high=3600.0, live=True)
    on_controller_loss: str = param('vent', 'on a lost controller: vent (arm at vent_pressure, '
                                    'wrist at 0) or hold the last set-points, republished at '
                                    'rate_hz', choices=ACTIONS, live=True)
    command_timeout: float = param(0.5, 'old name of controller_loss_timeout [s]', low=0.001,
                                   high=3600.0, live=True)
    stale_action: str = param('vent', 'old name of on_controller_loss', choices=ACTIONS,
                              live=True)
    vent_pressure: float = param(0.0, 'arm pressure commanded when venting [Pa]', low=0.0,
                                 high=MAX_BAR * PASCAL_PER_BAR, live=True)
    on_exit: str = param('vent', 'when the bridge stops (Ctrl-C, SIGTERM) after it sent '
                         'set-points: vent first, or hold (leave the last ones with the driver)',
                         choices=ACTIONS, live=True)
    reading_timeout: float = param(0.5, 'bha_readings older than this are reported stale in '
                                   'diagnostics and warned about [s]', low=0.001, high=3600.0,
                                   live=True)
    silence_warn_period: float = param(10.0, 'while no bha_readings arrive: least time between '
                                       'two warnings [s]', low=0.1, high=3600.0, live=True)
    publish_idle: bool = param(False, 'before the first valid command, publish the vent '
                               'set-points at rate_hz (false: publish nothing until a command '
                               'arrives)', live=True)
    rate_hz: float = param(50.0, 'watchdog rate, and publication rate of hold/vent set-points '
                           '[Hz]', low=1.0, high=1000.0, live=True)
    driver_command_topic: str = param('/set_bha_pressures', "topic of the driver's "
                                      'SetBHAPressures')
    driver_readings_topic: str = param('/bha_readings', "topic of the driver's BHAReadings")
    string_pot_names: tuple = param(STRING_POTS, 'names of the string potentiometers, in the '
                                    'order of BHAReadings.cablepull')
    frame_id: str = param('cbha_base', 'frame_id of string_pots')
    diagnostics_period: float = param(1.0, 'period of /diagnostics [s]', low=0.05, high=60.0)
    log_throttle: float = param(1.0, 'least time between two logs of rejected inputs [s]',
                                low=0.0, high=3600.0, live=True)

    def __post_init__(self):
        """Check the valve names and the wrist set-points against the driver's channels."""
        names = tuple(self.valve_names)
        if not names or len(names) > N_CHANNELS:
            raise ValueError(f'valve_names must name 1..{N_CHANNELS} channels, got {list(names)}')
        robotino_bar_command(np.zeros(len(names)), names, self.max_bar, self.wrist_bar)
        if not all(math.isfinite(v) and 0.0 <= v <= self.max_bar for v in self.wrist_bar):
            raise ValueError(f'wrist_bar must be 2 values in [0, max_bar = {self.max_bar:g}] bar,'
                             f' got {list(self.wrist_bar)}')
        if self.vent_pressure > self.max_pressure:
            raise ValueError(f'vent_pressure {self.vent_pressure:g} Pa is above max_pressure '
                             f'{self.max_pressure:g} Pa')
        for name, old_name in RENAMED.items():
            _one_of(self, name, old_name)   # both names agree, or one is left at its default

    @property
    def loss_timeout(self):
        """Return the controller-loss timeout [s]: ``controller_loss_timeout`` or its old name."""
        return _one_of(self, 'controller_loss_timeout', 'command_timeout')

    @property
    def loss_action(self):
        """Return what a lost controller gets: ``on_controller_loss`` or its old name."""
        return _one_of(self, 'on_controller_loss', 'stale_action')


def _one_of(params, name, old_name):
    """Return a parameter given under its name or its old one (refused: two values)."""
    defaults = {spec.name: spec.default for spec in fields(params)}
    value, old = getattr(params, name), getattr(params, old_name)
    if old == defaults[old_name] or old == value:
        return value
    if value == defaults[name]:
        return old
    raise ValueError(f'{name} {value!r} and its old name {old_name} {old!r} disagree: set only '
                     f'{name}')


def import_robotino_msgs():
    """
    Import the driver's message classes.

    Returns
    -------
    SetBHAPressures, BHAReadings : type
        The message classes of ``robotino_msgs.msg``.

    Raises
    ------
    ModuleNotFoundError
        With :data:`MISSING_MESSAGES` as its one-line message.

    """
    try:
        module = importlib.import_module('robotino_msgs.msg')
        return module.SetBHAPressures, module.BHAReadings
    except (ImportError, AttributeError) as exc:
        raise ModuleNotFoundError(MISSING_MESSAGES.format(error=exc)) from None


class RobotinoBridgeNode(Node):
    """
    The bridge between ``pressure_command`` (Pa) and the Robotino driver's messages (bar).

    Parameters
    ----------
    **kwargs
        Passed to ``rclpy.node.Node`` (``context``, ``namespace``, ``parameter_overrides``,
        ``cli_args``).

    Raises
    ------
    ParameterError
        On invalid parameters (the node is destroyed first).
    ModuleNotFoundError
        When ``robotino_msgs`` cannot be imported (one-line message; node destroyed first).

    """

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        try:
            self.params = declare_parameters(self, RobotinoBridgeParams, self._apply_parameters)
            self._setup_model()
        except (ParameterError, ModuleNotFoundError):
            self.destroy_node()
            raise
        self._setup_interfaces()

    def _setup_model(self):
        """Import the driver's messages; the channel map and the vent set-points."""
        self.set_pressures_type, self.readings_type = import_robotino_msgs()
        p = self.params
        self.channels = np.array([CHANNELS[name] for name in p.valve_names])
        self.vent_bar = self._vent_bar(p)

    def _setup_interfaces(self):
        """Create the bridge's state, topics and timers: the node runs."""
        p = self.params
        self.set_points = self.vent_bar.copy()
        self.sent = None
        self.measured = None
        self.stopped = None     # 'hold' or 'vent' after ~/hold, ~/vent, until ~/enable true
        self.ignored_while_stopped = 0
        self.decision = 'waiting'
        log = ThrottledLog(self.get_logger(), lambda: self.params.log_throttle)
        self.rejected = Rejections(log)
        self.forwarded = 0
        self.stale_published = 0
        self.readings = 0
        now = time.monotonic()
        self.command_watch = StalenessWatch(p.loss_timeout)
        self.reading_watch = StalenessWatch(p.reading_timeout)
        self.silence = SilenceWarning(p.reading_timeout, p.silence_warn_period, now)
        self.command_rate = RateMeter(now)
        self.reading_rate = RateMeter(now)
        self.driver_publisher = self.create_publisher(
            self.set_pressures_type, p.driver_command_topic, DRIVER_SET_POINTS_QOS)
        self.measured_publisher = self.create_publisher(
            Float64MultiArray, 'pressure_measured', MEASURED_QOS)
        self.pots_publisher = self.create_publisher(JointState, 'string_pots', MEASURED_QOS)
        self.create_subscription(Float64MultiArray, 'pressure_command', self._on_command,
                                 COMMAND_QOS)
        self.create_subscription(self.readings_type, p.driver_readings_topic, self._on_readings,
                                 DRIVER_READINGS_QOS)
        self.create_service(SetBool, '~/enable', self._on_enable)
        self.create_service(Trigger, '~/hold', lambda request, response: self._safe_state(
            'hold', response))
        self.create_service(Trigger, '~/vent', lambda request, response: self._safe_state(
            'vent', response))
        self.timer = self.create_timer(1.0 / p.rate_hz, self._on_timer)
        self.diagnostics = DiagnosticsPublisher(self, self._statuses, p.diagnostics_period)
        self.get_logger().info(
            f'{list(p.valve_names)} Pa -> {self.driver_publisher.topic_name} channels '
            f'{self.channels.tolist()} bar (cap {p.max_bar:g}, wrist {list(p.wrist_bar)}); '
            f'controller lost after {p.loss_timeout:g} s -> {p.loss_action}')

    @staticmethod
    def _vent_bar(p):
        return robotino_bar_command(np.full(len(p.valve_names), p.vent_pressure), p.valve_names,
                                    p.max_bar, (0.0, 0.0))

    def _apply_parameters(self, old, new):
        """Apply a change of the live parameters (checked; a ``ValueError`` refuses it)."""
        self._retune_model(new)
        self._retune_interfaces(new)
        self.params = new

    def _retune_model(self, new):
        """Live parameters of what ``_setup_model`` built."""
        self.vent_bar = self._vent_bar(new)

    def _retune_interfaces(self, new):
        """Live parameters of what ``_setup_interfaces`` built."""
        self.command_watch.timeout = new.loss_timeout
        self.reading_watch.timeout = self.silence.timeout = new.reading_timeout
        self.silence.period = new.silence_warn_period
        self.timer.timer_period_ns = int(round(1e9 / new.rate_hz))

    def destroy_node(self):
        """Vent first (``on_exit: vent``) when set-points were sent, then destroy the node."""
        publisher = getattr(self, 'driver_publisher', None)
        if (getattr(self, 'sent', None) is not None and self.params.on_exit == 'vent'
                and publisher in self.publishers):
            self._send(self.vent_bar)
            acknowledged = publisher.wait_for_all_acked(Duration(seconds=EXIT_ACK_TIMEOUT))
            self.get_logger().info('stopping: vented' + ('' if acknowledged else
                                   f' (not acknowledged within {EXIT_ACK_TIMEOUT:g} s)'))
        super().destroy_node()

    # commands -------------------------------------------------------------------------------
    def _on_command(self, message):
        values = command_array(message)
        p = self.params
        check = check_command(values, len(p.valve_names), p.max_pressure)
        if not check.ok:
            self.rejected.count(check.reason, f'rejected pressure_command: {check.detail}')
            return
        if self.stopped is not None:
            self.ignored_while_stopped += 1
            return
        self.command_rate.add()
        self.command_watch.mark(time.monotonic())
        self.set_points = robotino_bar_command(values, p.valve_names, p.max_bar, p.wrist_bar)
        self._set_decision('run')
        self._send(self.set_points)
        self.forwarded += 1

    def _on_timer(self):
        now = time.monotonic()
        if self.silence.due(now, self.reading_watch.last):
            topic = self.resolve_topic_name(self.params.driver_readings_topic)
            self.get_logger().warn(f'no bha_readings from the driver on {topic} for '
                                   f'{self.silence.timeout:g} s or more: is the Robotino driver '
                                   'running?')
        if self.stopped is not None:
            self._send_stopped()
            return
        if not self.command_watch.stale(now):
            return
        if self.decision != 'waiting':
            self._set_decision(self.params.loss_action)
            self.stale_published += 1
        action = watchdog_action(self.decision, self.params.publish_idle)
        if action is not None:
            self._send(self.set_points if action == 'hold' else self.vent_bar)

    def _on_enable(self, request, response):
        """``~/enable``: true forwards commands again; false vents (as ``~/vent``)."""
        if not request.data:
            return self._safe_state('vent', response)
        self.stopped = None
        response.success, response.message = True, 'enabled: forwarding pressure_command'
        self.get_logger().info(response.message)
        return response

    def _safe_state(self, action, response):
        """``~/hold``, ``~/vent``: stop forwarding; hold the last set-points or vent."""
        self.stopped = action
        if action == 'hold' and self.sent is not None:
            self.set_points = self.sent     # what the driver has now (after a vent: vented)
        self._send_stopped()
        held = ('holding the last set-points' if self.sent is not None
                else 'holding (nothing sent yet: nothing to hold)')
        response.message = f'{"venting" if action == "vent" else held} until ~/enable true'
        response.success = True
        self.get_logger().warn(response.message)
        return response

    def _send_stopped(self):
        """Send what ``~/vent`` or ``~/hold`` keeps (hold before any set-point: nothing)."""
        if self.stopped == 'vent':
            self._send(self.vent_bar)
        elif self.sent is not None:
            self._send(self.set_points)

    def _set_decision(self, decision):
        if decision != self.decision:
            self.get_logger().info(f'{self.decision} -> {decision}')
            self.decision = decision

    def _send(self, bar):
        bar = np.asarray(bar, dtype=float)
        assert bar.shape == (N_CHANNELS,) and np.all(np.isfinite(bar))
        assert np.all(bar >= 0.0) and np.all(bar <= self.params.max_bar)
        self.driver_publisher.publish(self.set_pressures_type(pressures=bar.tolist()))
        self.sent = bar

    # readings -------------------------------------------------------------------------------
    def _on_readings(self, message):
        p = self.params
        try:
            pascal = robotino_pressures(message.pressures, p.valve_names)
        except ValueError as exc:
            self.rejected.count('readings.wrong_length', f'rejected bha_readings: {exc}')
            return
        if not np.all(np.isfinite(pascal)):
            self.rejected.count('readings.non_finite',
                                'rejected bha_readings: non-finite pressure')
            return
        self.reading_rate.add()
        self.reading_watch.mark(time.monotonic())
        self.readings += 1
        self.measured = pascal
        self.measured_publisher.publish(command_message(pascal, p.valve_names))
        pulls = list(message.cablepull)
        self.pots_publisher.publish(joint_state(
            string_pot_names(p.string_pot_names, len(pulls)), pulls, message.stamp, p.frame_id))

    # diagnostics ----------------------------------------------------------------------------
    def _statuses(self):
        now = time.monotonic()
        p = self.params
        total = self.rejected.total
        values = {'decision': self.decision, 'stopped': self.stopped or '',
                  'ignored_while_stopped': self.ignored_while_stopped,
                  'forwarded_commands': self.forwarded,
                  'stale_set_points_published': self.stale_published,
                  'command_rate_hz': self.command_rate.rate(now),
                  'command_age_s': self.command_watch.age(now),
                  'readings': self.readings, 'reading_rate_hz': self.reading_rate.rate(now),
                  'reading_age_s': self.reading_watch.age(now), **self.rejected.key_values(),
                  'sent_bar': ' '.join(f'{v:.3f}' for v in self.sent) if self.sent is not None
                  else ''}
        if self.sent is not None and self.measured is not None:
            commanded = robotino_pressures(self.sent, p.valve_names)
            for name, error in zip(p.valve_names, self.measured - commanded):
                values[f'measured_minus_commanded_pa.{name}'] = float(error)
        if self.stopped is not None:
            level, message = WARN, f'stopped by ~/{self.stopped}: not forwarding'
        elif self.decision in ('hold', 'vent'):
            level, message = WARN, f'command stream stale: {self.decision}'
        elif self.reading_watch.stale(now):
            level, message = WARN, 'no recent bha_readings from the driver'
        elif total:
            level, message = WARN, f'{total} rejected messages'
        else:
            level, message = OK, 'forwarding' if self.decision == 'run' else 'waiting'
        return [make_status(self.get_name(), 'driver', level, message, values)]


def main(argv=None):
    """
    Run the ``robotino_bridge`` node until SIGINT/SIGTERM.

    Parameters
    ----------
    argv : list of str, optional
        Command line (default ``sys.argv``), e.g. ``['robotino_bridge', '--ros-args',
        '--params-file', 'config/robotino_bridge.yaml', '-r', '__ns:=/cbha']``.

    Returns
    -------
    int
        0 on a clean shutdown, 2 on invalid parameters or a missing ``robotino_msgs``.

    """
    return run_node(RobotinoBridgeNode, NODE_NAME, argv, params_class=RobotinoBridgeParams)


if __name__ == '__main__':
    sys.exit(main())
