"""
``inverse_solver``: the controller node (``docs/nodes.md``; the tick: ``docs/design.md``).

Subscribes ``target`` (PointStamped, reliable) and, in closed-loop mode, ``tip/measured``
(PointStamped, sensor data; ``feedback_topic``: e.g. ``tip/estimated`` of ``shape_estimator``)
and, when set, ``payload_topic`` (Float64, kg), ``section_stiffness_topic`` (Float64MultiArray,
one stiffness factor per scene section) and ``actuator_gain_topic`` (Float64MultiArray, one gain
per valve) into the model's loads, links and cavities, and for each entry of ``wrench_frames``
``wrench/tip`` or ``wrench/frame_<i>`` (WrenchStamped: a load on that frame,
:mod:`cbha_inverse.ros.common.wrenches`), and ``obstacles`` (MarkerArray, the whole set the
collision spheres keep clear of, replacing the scene's: ``docs/obstacles.md``);
publishes ``pressure_command`` (Float64MultiArray, gauge Pa, order = ``valve_names``, reliable;
with ``command_kind: displacement`` ``tendon_displacement_command``, the tendon drives' positions
[m] that hold the tick's tensions at the model's state),
``/diagnostics`` (~1 Hz), ``backbone`` (MarkerArray) and, every ``tf_every_n_ticks`` ticks, the
model frames and the tip on ``/tf`` (:mod:`cbha_inverse.ros.common.tf`; needs tf2_msgs); the
obstacles it keeps clear of are drawn on ``model_obstacle_markers`` and sent as frames
``model_obstacle_<name>`` on ``/tf_static`` (both latched, again on every replacement).

Nothing is published before the first valid target (``publish_idle: true`` publishes the vent
command meanwhile). With ``trigger: target`` a valid target is solved and its command published
inside the target callback (lowest target-to-command latency); the timer at ``rate_hz`` ticks the
solver only when no target came during the last period, so a target sent once, or one that stops
arriving, stays the set-point and the model keeps converging to it. What holds or vents
(``stale_action``) is stale feedback in closed loop. That timer and the stamps follow the node
clock (``use_sim_time``: ``/clock``, e.g. from ``cbha_bag play --clock``); the staleness watchdog
(hold, vent, idle vent) runs on its own timer on the steady clock, so a paused or finished bag
still makes the node hold or vent. Services: ``~/enable`` (std_srvs/SetBool: false stops
ticking and does ``on_disable``, true resumes), ``~/hold`` and ``~/vent`` (std_srvs/Trigger: stop
ticking and republish the last command, or the vent command, at ``rate_hz`` until ``~/enable
true``: the consumers' controller-loss watchdogs see a live controller) and ``~/reset``
(std_srvs/Trigger: model state and closed-loop correction back to rest; the set-point stays).
A target that stops arriving is warned about once only when targets came as a stream (the one
before the last arrived within ``target_timeout`` of it); a target sent once is a set-point, held
without a warning. Every input passes
:mod:`cbha_inverse.robot.safety` first; a rejected message is counted and logged (throttled) and
the last valid command stays. Every command passes
:class:`cbha_inverse.robot.safety.CommandGate`: never NaN, never outside ``[0, p_max]``.

Besides ``target`` (the first effector's): ``targets/<effector>`` per scene effector,
``target_pose`` and ``target_poses/<effector>`` (PoseStamped: with the orientation an ``axis``
or ``pose`` effector constrains, ``docs/effectors.md``), the action
``~/follow_trajectory`` (control_msgs/FollowJointTrajectory) and the teleop topics
``~/delta_twist_cmds`` and ``~/pose_target_cmds`` (:mod:`cbha_inverse.ros.nodes.commanding`,
``docs/commanding.md``); while a goal runs, the streaming topics are refused. ``touch``
(PoseStamped: the first effector's contact target, its position the contact point and its z
axis the surface's outward normal, pressing with a force within ``touch_force_bounds``;
``~/release_touch`` (std_srvs/Trigger) ends it: ``docs/touch.md``). A scene with
several effectors runs in open loop only (the closed loop corrects one measured tip).
"""

from dataclasses import dataclass
import math
import sys
import time

from cbha_inverse.core.actuation.effectors import rotation_of_quaternion
from cbha_inverse.core.inverse.episodes import StatusEpisodes
from cbha_inverse.core.inverse.qp import QP_SOLVERS
from cbha_inverse.core.inverse.results import HELD_STATUSES
from cbha_inverse.core.inverse.solver import TargetCorrector
from cbha_inverse.core.inverse.touch import checked_force_bounds
from cbha_inverse.core.sections import check_section_factors
from cbha_inverse.robot.ordering import DROPPED, StampOrder
from cbha_inverse.robot.robotino import ARM_VALVES
from cbha_inverse.robot.safety import (
    ACTIONS, check_point, command_bounds, CommandGate, controller_decision, StalenessWatch,
    valve_order, watchdog_action, WorkspaceBox)
from cbha_inverse.robot.targets import TargetHistory
from cbha_inverse.ros.common.conversions import (
    backbone_markers, point_values, SerializedCommand, stamp_ns)
from cbha_inverse.ros.common.diagnostics import (
    DiagnosticsPublisher, ERROR, make_status, OK, TimingStats, WARN)
from cbha_inverse.ros.common.obstacle_markers import obstacle_markers, obstacles_from_markers
from cbha_inverse.ros.common.params import (
    changes_text, declare_parameters, param, ParameterError)
from cbha_inverse.ros.common.qos import (COMMAND_WRITER_QOS, MARKER_QOS, MEASURED_QOS,
                                         OBSTACLE_MARKERS_QOS, OBSTACLES_QOS, TARGET_QOS)
from cbha_inverse.ros.common.realtime import MAX_REALTIME_PRIORITY, set_realtime_priority
from cbha_inverse.ros.common.rejections import Rejections, ThrottledLog
from cbha_inverse.ros.common.runner import run_node
from cbha_inverse.ros.common.tf import backbone_poses, make_broadcaster, obstacle_poses
from cbha_inverse.ros.common.tf_listener import make_static_listener
from cbha_inverse.ros.common.wrenches import wrench_frames, WrenchInputs
from cbha_inverse.ros.nodes.commanding import Commanding
from cbha_inverse.scene import load_scene
from geometry_msgs.msg import PointStamped, PoseStamped
import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from std_msgs.msg import Float64, Float64MultiArray
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import MarkerArray

NODE_NAME = 'inverse_solver'
EPISODE_TEXT = {'not_converged': 'model state off equilibrium: the effector {:.2f} mm from it',
                'unreachable': 'target beyond reach: the closest reachable point {:.2f} mm away',
                'obstacle': 'pushed against an obstacle: a collision sphere {:.2f} mm inside '
                            'the margin'}
"""What an episode's condition means, with its distance [mm]."""
EPISODE_ACTION = {'not_converged': 'narrowing the actuation step until it converges',
                  'unreachable': 'tracking the closest reachable point',
                  'obstacle': 'keeping as much clearance as the actuators allow'}
NOT_CONVERGED_ERROR_S = 1.0
"""An episode off equilibrium longer than this [s] is an ERROR in the diagnostics."""
NOT_CONVERGED_WARN_S = 0.1
"""Ticks off equilibrium are logged once they add up to this long [s] in an episode (at
``rate_hz``): the few ticks the model takes to converge after a jump of the target (ten at
100 Hz) are no condition to warn of."""


@dataclass(frozen=True)
class InverseSolverParams:
    """Parameters of the ``inverse_solver`` node."""

    scene: str = param('cbha.yaml', 'scene YAML: a file path, or a name in config/scenes')
    rate_hz: float = param(100.0, 'control tick rate [Hz]', low=1.0, high=2000.0, live=True)
    trigger: str = param('target', 'target: solve when a target arrives (and on the timer when '
                         'none came for a period); timer: solve on the timer only',
                         choices=('target', 'timer'))
    mode: str = param('open', 'open: model only (the paper); closed: integral correction from '
                      'tip/measured', choices=('open', 'closed'))
    valve_names: tuple = param(None, 'command order: a permutation of the scene actuators '
                               '(unset: the scene order; the CBHA scene order is the vendor '
                               f'channels 0-5, {", ".join(ARM_VALVES)})',
                               unset_type='string_array')
    max_pressure: float = param(150000.0, 'p_max [Pa] ceiling of every command (1.5 bar)',
                                low=0.0, high=1.0e7, live=True)
    command_kind: str = param('tension', 'tension: publish pressure_command (the actuation, N '
                              'or Pa); displacement: publish tendon_displacement_command, the '
                              "tendon drives' positions [m] that hold the tick's tensions at the "
                              "model's state (every actuator a cable with an axial_stiffness)",
                              choices=('tension', 'displacement'))
    target_timeout: float = param(0.5, 'a target older than this is reported stale [s] '
                                  '(steady clock; it stays the set-point, the model keeps '
                                  'converging to it)', low=0.001, high=3600.0, live=True)
    feedback_timeout: float = param(0.5, 'closed loop: measurement older than this is stale [s]',
                                    low=0.001, high=3600.0, live=True)
    stale_action: str = param('hold', 'closed loop, on stale feedback: hold the last command '
                              'or vent', choices=ACTIONS, live=True)
    on_disable: str = param('hold', '~/enable false: hold (republish the last command) or vent '
                            '(publish the vent command) at rate_hz until ~/enable true',
                            choices=ACTIONS, live=True)
    publish_idle: bool = param(False, 'before the first valid target, publish the vent command '
                               'at rate_hz (false: publish nothing until a target arrives)',
                               live=True)
    vent_pressure: float = param(0.0, 'safe pressure commanded when venting [Pa]',
                                 low=0.0, high=1.0e7, live=True)
    frame_id: str = param('cbha_base', 'frame of the model and the commands; a target or '
                          'tip/measured in another frame is transformed through /tf_static, or '
                          'refused with its frame named')
    feedback_topic: str = param('tip/measured', 'closed loop: the measured tip (PointStamped); '
                                'tip/estimated for the string-pot estimate of shape_estimator')
    payload_topic: str = param('', 'a known tip payload (std_msgs/Float64, kg) in the model '
                               'loads, e.g. payload/estimated of shape_estimator (empty: none)')
    max_payload: float = param(1.0, 'payloads beyond +-this are rejected [kg]', low=0.0,
                               high=100.0)
    max_payload_change: float = param(5.0e-3, 'the model payload moves toward each payload '
                                      'message by at most this [kg] (0: all the way)',
                                      low=0.0, high=100.0, live=True)
    section_stiffness_topic: str = param('', "the chain sections' stiffness factors "
                                         '(std_msgs/Float64MultiArray, one per scene section, '
                                         'chain order) in the model, e.g. sections/estimated '
                                         'of shape_estimator (empty: none)')
    max_section_change: float = param(5.0e-4, 'each model section factor moves toward each '
                                      'message by at most this [-] (0: all the way)',
                                      low=0.0, high=10.0, live=True)
    actuator_gain_topic: str = param('', "the cavities' gains on their effective area "
                                     '(std_msgs/Float64MultiArray, valve_names order) in the '
                                     'model, e.g. gains/estimated of shape_estimator (empty: '
                                     'none)')
    max_gain_change: float = param(2.0e-3, 'each model gain moves toward each message by at '
                                   'most this [-] (0: all the way)', low=0.0, high=10.0,
                                   live=True)
    wrench_frames: tuple = param(None, 'frames (tip or an index i) whose wrench/tip or '
                                 'wrench/frame_<i> topic (geometry_msgs/WrenchStamped, '
                                 "frame_id: cbha_base or the frame's cbha_frame_<i>) puts a "
                                 'known load into the model (unset: none; docs/loads.md)',
                                 unset_type='string_array')
    workspace_min: tuple = param((-0.3, -0.4, -0.4), 'workspace box lower corner [m]: targets '
                                 'and measurements outside are rejected', live=True)
    workspace_max: tuple = param((0.6, 0.4, 0.4), 'workspace box upper corner [m]', live=True)
    loop_gain: float = param(0.1, 'closed loop: integral gain per measurement [-]',
                             low=0.0, high=1.0, live=True)
    max_correction: float = param(0.03, 'closed loop: largest target correction [m]',
                                  low=0.0, high=1.0, live=True)
    plant_delay: float = param(0.015, 'closed loop with obstacles: delay from a command to its '
                               'effect in a measurement (transport + valve response) [s]: a '
                               'measurement is compared with the model of that long before',
                               low=0.0, high=1.0, live=True)
    newton_steps: int = param(1, 'Newton steps of the model per tick', low=1, high=20)
    relinearize_every: int = param(1, 'ticks between linearisations (1 = every tick, the paper; '
                                   'N > 1 re-solves the QP of the last linear model in between)',
                                   low=1, high=1000)
    max_step: float = param(1.0, 'largest change of each actuator per tick, as a fraction of its '
                            'range (1: none, the paper; e.g. 0.1: no jump of the arm when the '
                            'target jumps)', low=1e-3, high=1.0)
    qp_solver: str = param('active_set', 'QP of each tick: active_set (exact KKT solution of '
                           'the small box QP, proxsuite takes over if it does not converge), '
                           'proxsuite (dense, warm-started) or gauss_seidel (the paper)',
                           choices=QP_SOLVERS)
    marker_period: float = param(0.1, 'period of the backbone markers [s]', low=0.01, high=60.0)
    tf_every_n_ticks: int = param(10, 'publish the model frames (cbha_frame_<i>) and the tip '
                                  '(cbha_tip) on /tf every N solver ticks (10: 10 Hz at 100 Hz; '
                                  '0 = off)', low=0, high=1000000, live=True)
    diagnostics_period: float = param(1.0, 'period of /diagnostics [s]', low=0.05, high=60.0)
    log_throttle: float = param(1.0, 'least time between two logs of rejected inputs [s]',
                                low=0.0, high=3600.0, live=True)
    realtime_priority: int = param(0, 'SCHED_FIFO priority of the control thread (1-98, as '
                                   'ros2_control thread_priority; refused without root or '
                                   'CAP_SYS_NICE: a warning); 0 = the normal scheduler',
                                   low=0, high=MAX_REALTIME_PRIORITY)
    # commanding (docs/commanding.md, cbha_inverse.ros.nodes.commanding)
    approach_speed: float = param(0.02, '~/follow_trajectory: top speed [m/s] of the approach '
                                  'from where the effectors are to the first waypoint (later '
                                  'waypoints are delayed for it)', low=1e-4, high=10.0,
                                  live=True)
    default_path_tolerance: float = param(0.0, '~/follow_trajectory: path tolerance [m] of an '
                                          'effector the goal gives none (0: unchecked)',
                                          low=0.0, high=10.0, live=True)
    default_goal_tolerance: float = param(0.001, '~/follow_trajectory: goal tolerance [m] of '
                                          'an effector the goal gives none (0: unchecked)',
                                          low=0.0, high=10.0, live=True)
    default_path_angle_tolerance: float = param(0.0, '~/follow_trajectory: path angle '
                                                'tolerance [rad] of an axis or pose effector '
                                                'the goal gives none (0: unchecked)', low=0.0,
                                                high=math.pi, live=True)
    default_goal_angle_tolerance: float = param(0.0175, '~/follow_trajectory: goal angle '
                                                'tolerance [rad] of an axis or pose effector '
                                                'the goal gives none (0: unchecked)', low=0.0,
                                                high=math.pi, live=True)
    default_goal_time_tolerance: float = param(1.0, '~/follow_trajectory: time [s] after the '
                                               'last waypoint the goal tolerance may take when '
                                               'the goal gives none', low=0.0, high=3600.0,
                                               live=True)
    reach_samples: int = param(0, 'goals and teleop: actuations sampled at start for the '
                               'reachable set of each effector (scene.reach: its hull lies '
                               'inside the true reach, finer with more; config/inverse_solver.'
                               'yaml: 1000, ~1.4 s on the CBHA; 0: no reach check)', low=0,
                               high=100000)
    reach_margin: float = param(0.005, 'a goal waypoint or teleop target up to this far beyond '
                                'the sampled reachable set is accepted [m] (the CBHA: the '
                                "paper's 60 mm circle is 2.4 mm beyond the hull of 1000 "
                                'samples)', low=0.0, high=1.0, live=True)
    feedback_every_n_ticks: int = param(10, '~/follow_trajectory feedback every N solver ticks',
                                        low=1, high=100000, live=True)
    teleop_max_speed: float = param(0.05, 'teleop: top speed of the target [m/s] (twist and '
                                    'pose commands)', low=1e-4, high=10.0, live=True)
    touch_force_bounds: tuple = param((0.2, 0.4), 'touch: the force bounds [f_min, f_max] '
                                      '[N] of a contact target on the touch topic '
                                      '(0 <= f_min <= f_max; docs/touch.md)', live=True)
    teleop_timeout: float = param(0.2, 'teleop: the target stops (holds) when no command came '
                                  'for this long [s] (steady clock)', low=0.001, high=60.0,
                                  live=True)


class InverseSolverNode(Node):
    """
    The controller: target (+ measurement) in, pressure command out.

    Parameters
    ----------
    **kwargs
        Passed to ``rclpy.node.Node`` (``context``, ``namespace``, ``parameter_overrides``).

    Raises
    ------
    ParameterError
        On invalid parameters or a scene that does not fit them (the node is destroyed first).

    """

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        try:
            self.params = declare_parameters(self, InverseSolverParams, self._apply_parameters)
            self._setup_model()
        except (ValueError, FileNotFoundError, KeyError) as exc:
            self.destroy_node()
            raise ParameterError(str(exc)) from None
        self._setup_interfaces()

    def _setup_interfaces(self):
        """Create the controller's state, topics, services and timers: the node runs."""
        p = self.params
        self.period = 1.0 / p.rate_hz
        self.target = None
        self.target_history = TargetHistory()
        self.target_error = math.nan
        self.measured = None
        self.target_watch = StalenessWatch(p.target_timeout)
        self.feedback_watch = StalenessWatch(p.feedback_timeout)
        self.measured_order = StampOrder()
        self.command = self.vent_command.copy()
        self.decision = 'waiting'
        self.told_no_feedback = False
        self.enabled = True
        self.stopped = None     # while disabled: 'hold' or 'vent' (~/hold, ~/vent, on_disable)
        self.resets = 0
        self.target_stale = False
        self.target_streamed = False    # the last target came within target_timeout of another
        self.told_stale_target = False
        self.last_result = None
        self.last_goal = None        # the corrected target of last_result's tick [m]
        self._last_solve = -math.inf
        self.log = ThrottledLog(self.get_logger(), lambda: self.params.log_throttle)
        self.rejected = Rejections(self.log)
        self.published = 0
        self.ticks = 0
        self.statuses = {}
        # ticks off equilibrium or beyond reach: logged once per episode, in the diagnostics
        self.episodes = StatusEpisodes()
        self.episode_told = set()   # the ongoing episode's conditions already logged
        self.tick_times = TimingStats()
        self.latencies = TimingStats()
        # the thread's CPU time over the same window: latency minus it is time spent waiting
        # for a core (docs/nodes.md, "Latency")
        self.latency_cpu = TimingStats()
        self.command_publisher = self.create_publisher(
            Float64MultiArray, 'pressure_command' if self.drives is None
            else 'tendon_displacement_command', COMMAND_WRITER_QOS)
        # the command's serialized message, its pressures replaced per command
        self.command_bytes = SerializedCommand(self.valve_names)
        self.marker_publisher = self.create_publisher(MarkerArray, 'backbone', MARKER_QOS)
        self.tf = make_broadcaster(self)
        self.static_tf = make_static_listener(self)
        self.create_subscription(PointStamped, 'target', self._on_target, TARGET_QOS)
        self.create_subscription(PointStamped, p.feedback_topic, self._on_measured, MEASURED_QOS)
        if p.payload_topic:
            self.create_subscription(Float64, p.payload_topic, self._on_payload, MEASURED_QOS)
        if p.section_stiffness_topic:
            self.create_subscription(Float64MultiArray, p.section_stiffness_topic,
                                     self._on_sections, MEASURED_QOS)
        if p.actuator_gain_topic:
            self.create_subscription(Float64MultiArray, p.actuator_gain_topic,
                                     self._on_gains, MEASURED_QOS)
        self.obstacle_updates = 0
        self.create_subscription(MarkerArray, 'obstacles', self._on_obstacles, OBSTACLES_QOS)
        # the obstacles the model keeps clear of, latched (the plant draws its own)
        self.obstacle_publisher = self.create_publisher(MarkerArray, 'model_obstacle_markers',
                                                        OBSTACLE_MARKERS_QOS)
        self.obstacle_tf = make_broadcaster(self, static=True)
        self._publish_obstacles()
        self.wrenches = WrenchInputs(
            self, p.wrench_frames, self.scene.model.n_links, self.scene.loads, p.frame_id,
            self._on_loads, lambda reason, detail: self._count_rejected('wrench', reason, detail))
        self.create_service(SetBool, '~/enable', self._on_enable)
        self.create_service(Trigger, '~/hold', lambda request, response: self._safe_state(
            'hold', response))
        self.create_service(Trigger, '~/vent', lambda request, response: self._safe_state(
            'vent', response))
        self.create_service(Trigger, '~/reset', self._on_reset)
        self.create_subscription(PoseStamped, 'touch', self._on_touch, TARGET_QOS)
        self.create_service(Trigger, '~/release_touch', self._on_release_touch)
        self.commanding = Commanding(self)
        self.timer = self.create_timer(self.period, self._on_timer)
        self.watchdog_timer = self.create_timer(self.period, self._on_watchdog,
                                                clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.marker_timer = self.create_timer(p.marker_period, self._publish_markers)
        self.diagnostics = DiagnosticsPublisher(self, self._statuses, p.diagnostics_period)
        self.get_logger().info(
            f'scene {self.scene.name}: {len(self.valve_names)} valves {list(self.valve_names)}, '
            f'p_max {self.upper.max():g}, {p.mode} loop, trigger {p.trigger} at {p.rate_hz:g} Hz,'
            f' stale -> {p.stale_action}, disable -> {p.on_disable}; '
            f'{self.command_publisher.topic_name}')
        refused = set_realtime_priority(p.realtime_priority)
        if refused:
            self.get_logger().warn(f'{refused}; the control thread stays under the normal '
                                   'scheduler')
        elif p.realtime_priority:
            self.get_logger().info(f'control thread: SCHED_FIFO priority {p.realtime_priority}')

    def _setup_model(self):
        """Load the scene, build the solver and the command order and bounds."""
        p = self.params
        self.scene = load_scene(p.scene)
        if len(self.scene.effector_names) != 1 and p.mode == 'closed':
            raise ValueError(f'scene {self.scene.name} has effectors '
                             f'{list(self.scene.effector_names)}; the closed loop drives exactly '
                             'one (one measured tip)')
        self.valve_names, self.order = valve_order(self.scene.actuator_names, p.valve_names)
        wrench_frames(p.wrench_frames, self.scene.model.n_links)  # refused here, not later
        self.drives = None
        if p.command_kind == 'displacement':
            self.drives = self.scene.tendon_drives
            if self.drives is None or len(self.drives.names) != len(self.order) or not all(
                    np.isfinite(self.drives.axial_stiffness)):
                raise ValueError(f'command_kind displacement: scene {self.scene.name} needs '
                                 'every actuator a cable with a finite axial_stiffness')
        self.lower, self.upper, self.gate, self.vent_command, self.box = self._limits(p)
        checked_force_bounds(p.touch_force_bounds)
        self.solver = self.scene.make_inverse_solver(newton_steps=p.newton_steps,
                                                     relinearize_every=p.relinearize_every,
                                                     qp_solver=p.qp_solver, max_step=p.max_step)
        # compile the numba kernels (or load them from the cache) before any tick is timed
        started = time.perf_counter()
        self.solver.warm_up()
        self.get_logger().info(f'solver warm-up (numba kernels) took '
                               f'{time.perf_counter() - started:.2f} s')
        for warning in self.solver.warnings:
            self.get_logger().warning(f'scene {self.scene.name}: {warning}')
        # plant minus model position of every effector, measured (closed loop only)
        self.plant_offsets = np.zeros((len(self.scene.effector_names), 3))
        # the model's first effector at each tick (node clock [ns]), for plant_offsets
        self.model_history = TargetHistory()
        self.corrector = TargetCorrector(len(self.scene.effector_names),
                                         gain=p.loop_gain if p.mode == 'closed' else 0.0,
                                         max_correction=p.max_correction)

    def _limits(self, p):
        """Return the command bounds, command gate, vent command and workspace box of p."""
        lower, upper = command_bounds(self.scene.lower_bounds[self.order],
                                      self.scene.upper_bounds[self.order], p.max_pressure)
        gate = CommandGate(lower, upper)
        vent = gate(np.full(len(self.valve_names), float(p.vent_pressure)))
        return lower, upper, gate, vent, WorkspaceBox(p.workspace_min, p.workspace_max)

    def _apply_parameters(self, old, new):
        """Apply a change of the live parameters (checked; a ``ValueError`` refuses it)."""
        self._retune_model(new)
        self._retune_interfaces(new)
        self.params = new
        self.get_logger().info(f'parameters set: {changes_text(old, new)}')

    def _retune_model(self, new):
        """Live parameters of what ``_setup_model`` built (a ``ValueError`` refuses them)."""
        bounds = checked_force_bounds(new.touch_force_bounds)
        self.lower, self.upper, self.gate, self.vent_command, self.box = self._limits(new)
        if tuple(new.touch_force_bounds) != tuple(self.params.touch_force_bounds):
            for effector, touch in self.solver.touches.items():
                self.solver.set_touch(effector, touch.point, touch.normal, bounds)
        self.corrector.gain = new.loop_gain if new.mode == 'closed' else 0.0
        self.corrector.max_correction = new.max_correction

    def _retune_interfaces(self, new):
        """Live parameters of what ``_setup_interfaces`` built."""
        self.target_watch.timeout = new.target_timeout
        self.feedback_watch.timeout = new.feedback_timeout
        self.period = 1.0 / new.rate_hz
        for timer in (self.timer, self.watchdog_timer):
            timer.timer_period_ns = int(round(self.period * 1e9))

    # inputs ---------------------------------------------------------------------------------
    def _accepted_pose_position(self, topic, message):
        """Return the checked position of a PoseStamped, or None (:meth:`_accepted_point`)."""
        stamped = PointStamped()
        stamped.header = message.header
        position = message.pose.position
        stamped.point.x, stamped.point.y, stamped.point.z = position.x, position.y, position.z
        return self._accepted_point(topic, stamped)

    def _pose_rotation(self, topic, message):
        """
        Return a PoseStamped's orientation as a rotation matrix in the node's ``frame_id``.

        Call after :meth:`_accepted_pose_position` accepted its position: its frame is known.

        Raises
        ------
        ValueError
            On a quaternion that is not finite or not of unit length.

        """
        q = message.pose.orientation
        rotation = rotation_of_quaternion([q.x, q.y, q.z, q.w], f'{topic} orientation')
        frame = message.header.frame_id or self.params.frame_id
        if frame != self.params.frame_id:
            # the frame is known: the position passed the same transform
            rotation = self.static_tf.transform(frame, self.params.frame_id)[0] @ rotation
        return rotation

    def _accepted_point(self, topic, message, check_box=True):
        """Return the checked point of a message, or None (rejection counted and logged)."""
        # the message's three floats, an array only once accepted (docs/nodes.md, "Latency")
        values = point_values(message)
        frame = message.header.frame_id
        if frame != self.params.frame_id and self.static_tf is not None and frame:
            try:
                values = self.static_tf.transform_point(values, frame, self.params.frame_id)
            except (LookupError, ValueError) as exc:
                self._count_rejected(topic, 'unknown_frame', f'{exc} (publish its transform on '
                                     f'/tf_static, e.g. cbha_static_transform)')
                return None
            frame = self.params.frame_id
        check = check_point(values, frame, self.params.frame_id, self.box if check_box else None)
        if check.ok:
            return np.array(values)
        self._count_rejected(topic, check.reason, check.detail)
        return None

    def _count_rejected(self, topic, reason, detail):
        self.rejected.count(f'{topic}.{reason}', f'rejected {topic}: {detail}')

    def _on_payload(self, message):
        mass = float(message.data)
        if not abs(mass) <= self.params.max_payload:
            self._count_rejected('payload', 'out_of_range', f'{mass} kg')
            return
        self.solver.set_payload(mass, self.params.max_payload_change or None)
        self._prepare()

    def _on_loads(self, loads):
        """Put the loads of the ``wrench/<frame>`` topics into the model."""
        self.solver.set_loads(loads)
        self._prepare()

    def _on_obstacles(self, message):
        """Replace the model's obstacles by those of an ``obstacles`` message, or reject it."""
        obstacles, key, detail = obstacles_from_markers(message, self.params.frame_id)
        if obstacles is not None:
            try:
                self.solver.set_obstacles(obstacles)
            except ValueError as exc:
                key, detail = 'no_collision', str(exc)
        if key is not None:
            self._count_rejected('obstacles', key, detail)
            return
        self.obstacle_updates += 1
        self.get_logger().info(f'obstacles from the obstacles topic: '
                               f'{", ".join(o.name for o in obstacles) or "none"}')
        self._publish_obstacles()
        self._prepare()

    def _publish_obstacles(self):
        """Draw the model's obstacles and send their frames (the whole set replaces the last)."""
        self.obstacle_publisher.publish(obstacle_markers(
            self.solver.obstacles, self.get_clock().now().to_msg(), self.params.frame_id,
            rgba=(0.3, 0.5, 0.8, 0.4)))
        if self.obstacle_tf is not None:
            self.obstacle_tf.send(self.params.frame_id,
                                  *obstacle_poses(self.solver.obstacles, 'model_obstacle'))

    def _prepare(self):
        """Linearise the changed model now, off the target -> command path."""
        # (an unchanged payload keeps the prepared linearisation: then this does nothing)
        try:
            self.solver.prepare()
        except (ValueError, ArithmeticError, RuntimeError) as exc:
            self._count_failure('linearisation failed (the next tick retries)', exc)

    def _on_sections(self, message):
        factors = np.array(message.data, dtype=float)
        refused = check_section_factors(factors, len(self.solver.section_names))
        if refused is not None:
            self._count_rejected('sections', *refused)
            return
        self.solver.set_section_stiffness(factors, self.params.max_section_change or None)
        self._prepare()

    def _on_gains(self, message):
        gains = np.array(message.data, dtype=float)
        refused = check_section_factors(gains, self.order.size, 'actuator gain')
        if refused is not None:
            self._count_rejected('gains', *refused)
            return
        in_scene_order = np.empty(self.order.size)
        in_scene_order[self.order] = gains
        self.solver.set_actuator_gain(in_scene_order, self.params.max_gain_change or None)
        self._prepare()

    def _on_touch(self, message):
        """
        Take a contact target of the first effector (``touch``, ``docs/touch.md``).

        The pose's position is the contact point and the effector's target; its z axis the
        surface's outward normal; the bounds are ``touch_force_bounds``. The closed loop then
        corrects the tangential error only.
        """
        received, received_cpu = time.perf_counter(), time.thread_time()
        topic = 'touch'
        if self.commanding.refused(topic):
            return
        point = self._accepted_pose_position(topic, message)
        if point is None:
            return
        try:
            rotation = self._pose_rotation(topic, message)
            touch = self.solver.set_touch(0, point, rotation[:, 2],
                                          self.params.touch_force_bounds)
        except ValueError as exc:
            self._count_rejected(topic, 'bad_touch', str(exc))
            return
        self.corrector.set_touch_normal(0, touch.normal)
        f_min, f_max = touch.force_bounds
        self.get_logger().info(f'touch: {self.scene.effector_names[0]} on {point.round(4)} m, '
                               f'normal {touch.normal.round(3)}, force in [{f_min:g}, '
                               f'{f_max:g}] N')
        self._take_target(point, 0, stamp_ns(message.header.stamp), received, received_cpu)

    def _on_release_touch(self, request, response):
        """``~/release_touch``: the first effector tracks its target again, pressing nothing."""
        released = self.solver.clear_touch(0)
        self.corrector.set_touch_normal(0, None)
        response.success = True
        response.message = ('touch released: tracking the target' if released
                            else 'no touch to release')
        self.get_logger().info(response.message)
        return response

    def _on_target(self, message, effector=0, topic='target'):
        """Take a target of one effector (``target``: the first; ``targets/<name>``)."""
        received = time.perf_counter()
        received_cpu = time.thread_time()
        if self.commanding.refused(topic):
            return
        point = self._accepted_point(topic, message)
        if point is not None:
            self._take_target(point, effector, stamp_ns(message.header.stamp), received,
                              received_cpu)

    def _take_target(self, point, effector, stamp, received, received_cpu):
        """Make an accepted point one effector's target; tick now when triggered by targets."""
        if len(self.scene.effector_names) > 1:
            point = self.commanding._targets_with([effector], point)
        self._set_target(point, stamp)
        if self.params.trigger == 'target' and self._decide() == 'run':
            published, published_cpu = self._solve_and_publish()
            self.latencies.add(published - received)
            self.latency_cpu.add(published_cpu - received_cpu)

    def _set_target(self, point, stamp=None):
        """Make ``point`` ((3,) or (k, 3) [m]) the set-point, current from ``stamp`` [ns]."""
        if stamp is None:
            stamp = self.get_clock().now().nanoseconds
        self.target = point
        self.target_history.add(stamp, point)
        now = time.monotonic()
        # a stream: this target came within target_timeout of the one before
        self.target_streamed = not self.target_watch.stale(now)
        self.target_watch.mark(now)

    def _on_measured(self, message):
        point = self._accepted_point('tip/measured', message)
        if point is None:
            return
        # a duplicated or reordered (older) sample is not integrated twice or backwards
        stamp = stamp_ns(message.header.stamp)
        verdict = self.measured_order.admit(stamp, self.feedback_watch.stale(time.monotonic()))
        if verdict in DROPPED:
            self._count_rejected('tip/measured', verdict, f'stamp {stamp} ns is {verdict} '
                                 f'(last used {self.measured_order.last} ns)')
            return
        self.measured = point
        self.feedback_watch.mark(time.monotonic())
        if self.params.mode == 'closed' and self.target is not None and self.enabled:
            # anti-windup: while a bound, the reach or the model's convergence holds the tip, no
            # integration outward along the gap the model predicts (``TargetCorrector``)
            result = self.last_result
            saturated = result is not None and result.status in HELD_STATUSES
            predicted_gap = None if result is None else self.last_goal - result.effector_positions
            # the target of the measurement's own time: delivery delays and bursts of
            # measurements stay out of the integral
            reference = self.target_history.at(stamp, self.target)
            self.corrector.update(reference[None], point[None], saturated=saturated,
                                  predicted_gap=predicted_gap)
            if self.solver.obstacles:
                # where the plant lies from the model, low-passed at the loop's gain: the
                # obstacle rows keep the plant's spheres clear (InverseSolver.set_plant_offsets)
                model = self.model_history.at(stamp - int(self.params.plant_delay * 1e9),
                                              self.solver.effector_positions()[0])
                offset = point - model
                self.plant_offsets[0] += self.corrector.gain * (offset - self.plant_offsets[0])
            self.target_error = float(np.linalg.norm(reference - point))

    # control --------------------------------------------------------------------------------
    def _decide(self):
        """Return this tick's decision: disabled, waiting, run, hold or vent (logged on change)."""
        now = time.monotonic()
        decision = controller_decision(self.enabled, self.target is not None,
                                       self.feedback_watch.stale(now),
                                       self.params.mode == 'closed', self.params.stale_action,
                                       has_feedback=self.measured is not None)
        logger = self.get_logger()
        if decision != self.decision:
            # rclpy refuses two severities from one call site: one call per severity
            if decision in ('hold', 'vent'):
                logger.warn(f'{self.decision} -> {decision}: no {self.params.feedback_topic} for '
                            f'{self.feedback_watch.age(now):.2f} s')
            else:
                logger.info(f'{self.decision} -> {decision}')
            self.decision = decision
        if decision == 'waiting' and self.target is not None and not self.told_no_feedback:
            self.told_no_feedback = True
            topic = self.resolve_topic_name(self.params.feedback_topic)
            logger.warn(f'closed loop, no measurement yet on {topic}: no command until one '
                        'arrives')
        target_stale = self.target is not None and self.target_watch.stale(now)
        if target_stale != self.target_stale:
            self.target_stale = target_stale
            # only a stream that stops is worth a warning; a target sent once is a set-point
            if target_stale and self.target_streamed:
                self.told_stale_target = True
                logger.warn(f'no target for {self.target_watch.age(now):.2f} s: the target '
                            'stream stopped; the last one stays the set-point')
            elif not target_stale and self.told_stale_target:
                self.told_stale_target = False
                logger.info('targets arrive again')
        return decision

    def _node_seconds(self):
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_timer(self):
        """Tick on the node clock: solve when no target was solved during the last period."""
        self.commanding.before_tick()
        if self._decide() == 'run' and (
                self.params.trigger == 'timer'
                or self._node_seconds() - self._last_solve >= 0.9 * self.period):
            self._solve_and_publish()

    def _on_watchdog(self):
        """Tick on the steady clock: hold or vent on stale feedback, idle vent if configured."""
        decision = self._decide()
        action = watchdog_action(decision, self.params.publish_idle)
        if decision == 'disabled':
            # held or vented: republished, so the consumers see a live controller (before any
            # command there is nothing to hold)
            action = self.stopped if self.stopped == 'vent' or self.published else None
        if action == 'hold':
            self._publish(self.command)
        elif action == 'vent':
            self._publish(self.vent_command, vent=True)

    def _on_enable(self, request, response):
        """``~/enable``: false stops ticking and does ``on_disable``, true resumes."""
        if not request.data:
            return self._safe_state(self.params.on_disable, response)
        self.enabled, self.stopped = True, None
        self._decide()
        response.success = True
        response.message = 'enabled: commanding'
        self.get_logger().info(response.message)
        return response

    def _safe_state(self, action, response):
        """``~/hold``, ``~/vent``: stop ticking; hold the last command or vent, until enabled."""
        self.enabled, self.stopped = False, action
        self._decide()
        if action == 'vent':
            self._publish(self.vent_command, vent=True)  # at once, then by the watchdog
        response.success = True
        held = 'holding the last command' if self.published else 'nothing to hold (no command yet)'
        response.message = (f'disabled: {"venting" if action == "vent" else held} until '
                            '~/enable true')
        self.get_logger().warn(response.message)
        return response

    def _on_reset(self, request, response):
        """``~/reset``: model state and closed-loop correction back to rest."""
        self.solver.reset()
        self.corrector.reset()
        self.plant_offsets[:] = 0.0
        self.episodes.reset()
        self.episode_told = set()
        self.last_result = None
        self.last_goal = None
        self.target_error = math.nan
        self._last_solve = -math.inf
        self.resets += 1
        response.success = True
        response.message = ('model and correction at rest; the next command starts from rest'
                            + ('' if self.target is None else ' toward the current target'))
        self.get_logger().info(response.message)
        return response

    def _solve_and_publish(self):
        """Tick, publish, prepare the next tick; return perf_counter and thread_time at publish."""
        start = time.perf_counter()
        goal = self.corrector.corrected(self.target)
        try:
            result = self.solver.step(goal)
        except (ValueError, ArithmeticError, RuntimeError) as exc:
            # a numerical failure must not kill the controller: hold, count, report ERROR
            self._count_failure('solver failed, holding the last command', exc)
            self._publish(self.command)
            return time.perf_counter(), time.thread_time()
        self._publish(result.actuation[self.order])
        published = time.perf_counter(), time.thread_time()
        if self.solver.obstacles:
            # the rows keep the plant's spheres clear (InverseSolver.set_plant_offsets)
            self.model_history.add(self.get_clock().now().nanoseconds,
                                   result.effector_positions[0].copy())
            self.solver.set_plant_offsets(self.plant_offsets)
        # the bookkeeping and the linearisation for the next tick come after the publication,
        # off the target -> command path (``docs/design.md``)
        self.last_result, self.last_goal = result, goal
        self.statuses[result.status] = self.statuses.get(result.status, 0) + 1
        self._account_episode(result)
        for warning in result.warnings:
            self.log.warning('solver_warning', warning)
        self._last_solve = self._node_seconds()
        self.ticks += 1
        try:
            self.solver.prepare()
        except (ValueError, ArithmeticError, RuntimeError) as exc:
            self._count_failure('linearisation failed (the next tick retries)', exc)
        self.tick_times.add(time.perf_counter() - start)
        every = self.params.tf_every_n_ticks
        if self.tf is not None and every and self.ticks % every == 0:
            self._publish_tf()
        return published

    def _account_episode(self, result):
        """
        Log each condition of an episode off equilibrium or beyond reach once, and its end.

        Beyond reach: at its first tick; off equilibrium: once its ticks add up to
        :data:`NOT_CONVERGED_WARN_S` (an episode that converges sooner is not logged). An
        episode that starts off equilibrium after a jump of the target and stays beyond reach
        says both.
        """
        figure = {'not_converged': result.equilibrium_gap,
                  'obstacle': result.obstacle_violation}.get(result.status,
                                                             result.predicted_error)
        _, ended = self.episodes.update(result.status, figure, time.monotonic())
        logger = self.get_logger()
        if ended is not None and self.episode_told:
            summary = ', '.join(f'{n} ticks {c} (worst {1e3 * ended.worst[c]:.2f} mm)'
                                for c, n in ended.ticks.items())
            logger.info(f'back to normal after {ended.duration:.2f} s: {summary}')
        if ended is not None:
            self.episode_told = set()
        episode = self.episodes.current
        if episode is None:
            return
        for condition, ticks in episode.ticks.items():
            due = condition == 'unreachable' or ticks * self.period >= NOT_CONVERGED_WARN_S
            if due and condition not in self.episode_told:
                self.episode_told.add(condition)
                text = EPISODE_TEXT[condition].format(1e3 * episode.figures[condition])
                logger.warning(f'{text} ({EPISODE_ACTION[condition]})')

    def _count_failure(self, what, exc):
        self.statuses['exception'] = self.statuses.get('exception', 0) + 1
        self.log.error('exception', f'{what}: {exc!r}')

    def _publish(self, command, vent=False):
        """
        Publish a command through the last gate; one that is not finite: the last again.

        With ``command_kind`` displacement the gated tensions go out as the drives' positions
        that hold them at the model's state (venting: every drive back to zero, the cables'
        lengths as built).
        """
        try:
            command = self.gate(command)
        except ValueError as exc:
            # only a solver output can fail: hold, vent and the last command passed the gate
            self.rejected.count('solver.non_finite', f'solver output rejected, holding: {exc}',
                                error=True)
            command = self.command
        self.command = command
        if self.drives is not None:
            command = self._displacements(command, vent)
        self.command_publisher.publish(self.command_bytes.serialize(command))
        self.published += 1

    def _displacements(self, command, vent):
        """Return the drives' positions [m], valve order, that hold a tension command."""
        if vent:
            return np.zeros(len(self.order))
        tensions = np.empty(len(self.order))
        tensions[self.order] = command
        return self.drives.displacements(self.solver.state, tensions)[self.order]

    def destroy_node(self):
        """Destroy the action server, then the node."""
        commanding = getattr(self, 'commanding', None)
        if commanding is not None:
            commanding.destroy()
        super().destroy_node()

    # outputs --------------------------------------------------------------------------------
    def _at_bounds(self):
        """Return the valves whose last command is at its lower and at its upper bound."""
        # (a tendon at 0 N is at its lower bound: normal; at the upper bound it cannot pull more)
        span = np.maximum(self.upper - self.lower, 1.0) * 1e-9
        names = np.asarray(self.valve_names)
        return (names[self.command <= self.lower + span].tolist(),
                names[self.command >= self.upper - span].tolist())

    def _publish_markers(self):
        self.marker_publisher.publish(backbone_markers(
            self.solver.state.positions,
            None if self.target is None else np.reshape(self.target, (-1, 3))[-1],
            self.get_clock().now().to_msg(), self.params.frame_id))

    def _publish_tf(self):
        state = self.solver.state
        self.tf.send(self.params.frame_id, *backbone_poses(
            state.positions, state.rotations, self.solver.effectors.frames[0],
            self.solver.effector_positions()[0]))

    def _statuses(self):
        now = time.monotonic()
        result = self.last_result
        at_lower, at_upper = self._at_bounds() if self.published else ([], [])
        values = {'mode': self.params.mode, 'decision': self.decision, 'enabled': self.enabled,
                  'stopped': self.stopped or '', 'on_disable': self.params.on_disable,
                  'resets': self.resets, 'target_stale': self.target_stale, 'ticks': self.ticks,
                  'published': self.published, 'last_status': result.status if result else '',
                  'qp_status': result.qp_status if result else '',
                  'residual_norm': result.residual_norm if result else math.nan,
                  'predicted_error_mm': 1e3 * result.predicted_error if result else math.nan,
                  'equilibrium_gap_mm': 1e3 * result.equilibrium_gap if result else math.nan,
                  'restorations': self.solver.restorations,
                  'obstacles': len(self.solver.obstacles),
                  'obstacle_updates': self.obstacle_updates,
                  'obstacle_rows': result.obstacle_rows if result else 0,
                  'touch': ','.join(self.scene.effector_names[e] for e in self.solver.touches),
                  'touch_force_n': _touch_force(result),
                  'touch_violation_n': result.touch_violation if result else math.nan,
                  'saturated': ','.join(np.asarray(self.scene.actuator_names)[
                      result.saturated].tolist()) if result else '',
                  'at_lower_bound': ','.join(at_lower), 'at_upper_bound': ','.join(at_upper),
                  'target_age_s': self.target_watch.age(now),
                  'feedback_age_s': self.feedback_watch.age(now),
                  'correction_mm': 1e3 * float(np.linalg.norm(self.corrector.correction)),
                  'measured_error_mm': 1e3 * self.target_error,
                  'command_pa': ' '.join(f'{v:.0f}' for v in self.command),
                  **self.tick_times.summary('tick'), **self.latencies.summary('latency'),
                  **self.latency_cpu.summary('latency_cpu'),
                  **{f'status.{k}': v for k, v in sorted(self.statuses.items())}}
        if self.params.section_stiffness_topic:
            values.update({f'section_stiffness.{name}': float(v) for name, v in
                           zip(self.solver.section_names, self.solver.section_stiffness)})
        if self.params.actuator_gain_topic:
            values.update({f'actuator_gain.{name}': float(v) for name, v in
                           zip(self.scene.actuator_names, self.solver.actuator_gain)})
        episode = self.episodes.current
        if result is not None and result.status == 'not_positive_definite':
            level, message = ERROR, 'model tangent not positive definite: holding'
        elif episode is not None:
            level = (ERROR if episode.condition == 'not_converged'
                     and episode.duration > NOT_CONVERGED_ERROR_S else WARN)
            worst = episode.worst[episode.condition]
            message = (EPISODE_TEXT[episode.condition].format(1e3 * episode.figure)
                       + f' for {episode.duration:.1f} s (worst {1e3 * worst:.2f} mm)')
        elif self.decision in ('hold', 'vent'):
            level, message = WARN, f'stale feedback: {self.decision}'
        elif self.decision == 'disabled':
            level, message = OK, ('stopped: venting' if self.stopped == 'vent' else
                                  'stopped: holding the last command')
        elif self.decision == 'waiting':
            level, message = OK, 'waiting for a target'
        elif self.target_stale:
            level, message = OK, 'no recent target: converging to the last one'
        else:
            level, message = OK, f'running ({result.status if result else "no tick yet"})'
        total = self.rejected.total
        inputs = make_status(self.get_name(), 'inputs', WARN if total else OK,
                             f'{total} rejected messages' if total else 'all inputs valid',
                             self.rejected.key_values())
        return [make_status(self.get_name(), 'control', level, message, values), inputs]


def _touch_force(result):
    """Return the largest contact force a tick predicts [N] (NaN without a contact target)."""
    forces = None if result is None else result.touch_forces
    if forces is None or not np.isfinite(forces).any():
        return math.nan
    return float(np.nanmax(forces))


def main(argv=None):
    """
    Run the ``inverse_solver`` node until SIGINT/SIGTERM.

    Parameters
    ----------
    argv : list of str, optional
        Command line (default ``sys.argv``), e.g. ``['inverse_solver', '--ros-args',
        '--params-file', 'config/inverse_solver.yaml', '-r', '__ns:=/cbha']``.

    Returns
    -------
    int
        0 on a clean shutdown, 2 on invalid parameters.

    """
    return run_node(InverseSolverNode, NODE_NAME, argv, params_class=InverseSolverParams)


if __name__ == '__main__':
    sys.exit(main())
