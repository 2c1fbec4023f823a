"""
``cbha_sim``: a simulated CBHA for hardware-free runs (the plant of closed-loop runs and tests).

Subscribes ``pressure_command`` (Float64MultiArray, gauge Pa in ``valve_names`` order, reliable)
and rejects malformed commands like a valve driver (wrong length, non-finite, outside
``[0, max_pressure]``: logged with throttling, counted, the last valid set-point stays). A valid
command takes effect after the transport ``latency``; the valve pressures follow it with a
first-order lag ``valve_time_constant`` (:class:`cbha_inverse.sim.valves.ValveLine`: exact for
piecewise-constant commands, whatever the tick times). Every tick at ``rate_hz``:

- the valve pressures are published on ``pressure_measured`` (Float64MultiArray, Pa in
  ``valve_names`` order, sensor data QoS: what ``robotino_bridge`` publishes from the real
  driver's readings), with Gaussian noise ``pressure_noise_std`` per valve (default 0; seeded
  from ``seed`` as a stream of its own, so the tip noise of a seed does not change with it);
- the plant (:class:`cbha_inverse.sim.plant.StaticPlant`: the scene loaded with a deliberate
  ``stiffness_scale`` error, per-section ``section_stiffness_scale`` and per-valve
  ``cavity_gain_scale`` errors and a ``base_offset`` applied as a scene calibration, and its
  own ``gravity``) is moved
  to the equilibrium of those valve pressures (noise-free) by warm-started Newton steps;
- the tip is published on ``tip/measured`` (PointStamped, sensor data QoS) with Gaussian noise
  ``noise_std`` (seeded) and, noise-free, on ``tip/true``.

With ``command_kind: displacement`` (a tendon scene whose cables have an ``axial_stiffness``)
it subscribes ``tendon_displacement_command`` instead (Float64MultiArray, the drives' positions
[m] from the straight chain's cable lengths, pulled in negative, in ``valve_names`` order,
accepted within half the shortest cable's rest length), lagged by the same line (a drive's
position loop); venting sets every drive back to zero.

Valves, plant and sensor noise are :class:`cbha_inverse.sim.arm.SimulatedArm`, the plant's
model errors :func:`cbha_inverse.sim.plant_errors.plant_errors`. Time (ticks, latency, valve lag,
stamps) is the node clock: with ``use_sim_time`` the plant runs on ``/clock``.

``tip_output: stereo`` replaces ``tip/measured`` by rendered stereo cameras (the tip marker drawn
into both cameras of ``camera_rig`` at ``camera_rate_hz``: ``stereo/{left,right}/image_raw`` and
``camera_info``, see :mod:`cbha_inverse.ros.common.sim_cameras`) for ``stereo_tracker``; ``both``
publishes both, ``none`` no tip measurement at all (a camera-less arm; ``tip/true`` stays).
OpenCV is imported only for stereo. ``payload_mass`` hangs a payload the controller does not
know at the tip. A scene with a ``sensors`` block also gets ``string_pots`` (sensor_msgs/
JointState, names and raw readings as ``robotino_bridge`` publishes them, the stamp of the plant
state) at ``string_pot_rate_hz`` (at most the tick rate), from the plant's true shape with
``string_pot_noise_std`` [m] and the plant's own ``string_pot_offset`` / ``string_pot_gain``
(:class:`cbha_inverse.sim.pots.SimulatedPots`): in the tick, after the ``pressure_measured`` the
state is the equilibrium of, as the driver's one message carries both (a pot reading and the
last pressures received before it are of the same instant). A fault for tests and demos:
``string_pot_stuck`` (a pot index, -1: none) freezes that pot's reading
``string_pot_stuck_after`` seconds after the first accepted command (after a ``~/reset``: the
next one). ``valve_stuck`` (a valve index, -1: none; live) keeps that valve at its vent
set-point whatever it is commanded (a valve stuck shut).

Controller loss: once the commands come as a stream (a valid command within
``controller_loss_timeout`` of the previous one, as a controller publishes them at its tick rate),
a stream that stops for ``controller_loss_timeout`` (steady clock) is a lost controller (a crash, a
kill, a cut network): ``on_controller_loss: vent`` sends the vent set-points (every valve at its
lower bound, 0 Pa) into the valve line, so the pressures fall through the same latency and
first-order lag as for any command, as a real valve vents; ``hold`` keeps the last set-point.
A single command (a test rig, ``ros2 topic pub --once``) is a set-point the plant keeps: it arms
nothing. A command of the wrong length is rejected like any bad command, but
``stop_after_wrong_length`` of them in a row, all of one length, are a controller built for
another scene: the simulator stops with one line naming both lengths and the likely cause (exit
2), instead of rejecting every message.

Obstacles (``docs/obstacles.md``): the plant touches the scene's ``obstacles`` with its
collision spheres through a frictionless penalty of stiffness ``contact_stiffness``. The
``obstacles`` topic (visualization_msgs/MarkerArray of SPHERE, CUBE and CYLINDER markers in
``frame_id``, :mod:`cbha_inverse.ros.common.obstacle_markers`) replaces them at run time, each
message the whole set; a message with a marker of another shape, a non-finite or non-positive
size, another frame or a duplicate name is rejected (logged, counted), the obstacles kept. The
obstacles are drawn on ``obstacle_markers`` (latched) and sent as frames ``obstacle_<name>`` on
``/tf_static`` (latched, again on every replacement; :mod:`cbha_inverse.ros.common.tf`); every
converged tick publishes its contacts on ``contacts`` (Float64MultiArray, one row per contact:
frame, point, normal, penetration, force, in ``frame_id``, after ``tip/true``), the sum of the
tip sphere's contact forces on ``tip/contact_force`` (WrenchStamped, ``frame_id``: the force a
touching tip presses with, ``docs/touch.md``) and, while there are any and once when they end,
as points and force arrows on ``contacts/markers``. The diagnostics report the smallest
clearance of the collision spheres to the obstacles, this tick's (``min_clearance_m``) and the
lowest since the start or the last ``~/reset`` (``lowest_clearance_m``; negative: a
penetration).

Service ``~/reset`` (std_srvs/Trigger): plant, valves and pending commands back to rest.

External loads: for each entry of ``wrench_frames`` the plant takes a load on that frame from
``wrench/tip`` or ``wrench/frame_<i>`` (WrenchStamped, :mod:`cbha_inverse.ros.common.wrenches`),
on top of its scene's; the next tick is their equilibrium.
"""

from dataclasses import dataclass
import math
import sys
import time

from cbha_inverse.core.contact import frame_contact_force
from cbha_inverse.errors import CONFIG_ERROR_EXIT
from cbha_inverse.robot.robotino import ARM_VALVES
from cbha_inverse.robot.safety import (ACTIONS, check_command, check_displacement_command,
                                       command_bounds, StalenessWatch, valve_order)
from cbha_inverse.ros.common.conversions import (command_array, command_message,
                                                 joint_state, point_stamped)
from cbha_inverse.ros.common.diagnostics import (DiagnosticsPublisher, make_status, OK,
                                                 TimingStats, WARN)
from cbha_inverse.ros.common.loading import end_process
from cbha_inverse.ros.common.obstacle_markers import (contact_array, contact_markers,
                                                      obstacle_markers, obstacles_from_markers)
from cbha_inverse.ros.common.params import declare_parameters, param, ParameterError
from cbha_inverse.ros.common.qos import (COMMAND_QOS, MARKER_QOS, MEASURED_QOS,
                                         OBSTACLE_MARKERS_QOS, OBSTACLES_QOS)
from cbha_inverse.ros.common.rejections import Rejections, ThrottledLog
from cbha_inverse.ros.common.runner import run_node
from cbha_inverse.ros.common.tf import make_broadcaster, obstacle_poses
from cbha_inverse.ros.common.wrenches import wrench_frames, WrenchInputs
from cbha_inverse.scene import load_scene
from cbha_inverse.scene.calibration import Calibration, finite_triple
from cbha_inverse.sim.arm import SimulatedArm
from cbha_inverse.sim.plant_errors import plant_errors
from cbha_inverse.sim.pots import SimulatedPots
from geometry_msgs.msg import PointStamped, WrenchStamped
import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

NODE_NAME = 'cbha_sim'
LOSS_WATCH_PERIOD = 0.01
"""Period [s] of the controller-loss watchdog (steady clock): a loss acts within it."""


@dataclass(frozen=True)
class CbhaSimParams:
    """Parameters of the ``cbha_sim`` node."""

    scene: str = param('cbha.yaml', 'plant scene YAML: a file path, or a name in config/scenes')
    stiffness_scale: float = param(0.9, 'plant stiffness / nominal stiffness (model error) [-]',
                                   low=0.01, high=100.0)
    section_stiffness_scale: tuple = param(
        (1.0,), 'plant stiffness error per chain section, scene section order, on top of '
        'stiffness_scale (one value: every section) [-]')
    cavity_gain_scale: tuple = param(
        (1.0,), 'plant effective-area error per cavity, valve_names order (one value: every '
        'cavity) [-]')
    base_offset: tuple = param((0.0, 0.0, 0.0), 'plant base position error in cbha_base (the '
                               'tracker registration error the tips are measured with) [m]')
    gravity: tuple = param((0.0, 0.0, -9.81), 'plant gravity in cbha_base [m/s^2]')
    valve_names: tuple = param(None, 'command order: a permutation of the scene actuators '
                               '(unset: the scene order; the CBHA scene order is the vendor '
                               f'channels 0-5, {", ".join(ARM_VALVES)})',
                               unset_type='string_array')
    max_pressure: float = param(150000.0, 'driver limit [Pa]: commands above are rejected',
                                low=0.0, high=1.0e7, live=True)
    command_kind: str = param('tension', 'what the commands set: tension (pressure_command, '
                              'N or Pa) or displacement (tendon_displacement_command: the '
                              "cables' drive positions [m] from the straight chain, pulled in "
                              'negative; every actuator a cable with an axial_stiffness)',
                              choices=('tension', 'displacement'))
    valve_time_constant: float = param(0.01, 'first-order valve response [s] (paper: 10 ms)',
                                       low=0.0, high=10.0, live=True)
    latency: float = param(0.003, 'transport latency command -> valves [s] (paper: 3 ms)',
                           low=0.0, high=10.0, live=True)
    rate_hz: float = param(100.0, 'plant update and tip publication rate [Hz]',
                           low=1.0, high=2000.0, live=True)
    noise_std: float = param(0.0002, 'standard deviation of the tip measurement noise per axis '
                             '[m]', low=0.0, high=0.1, live=True)
    pressure_noise_std: float = param(0.0, 'standard deviation of the noise on '
                                      'pressure_measured per valve [Pa]', low=0.0, high=1.0e6,
                                      live=True)
    seed: int = param(0, 'seed of the measurement noise (tip and pressures: separate streams)',
                      low=0, high=2 ** 31 - 1)
    tolerance: float = param(1e-6, 'static equilibrium residual tolerance [N, N*m]',
                             low=1e-14, high=1.0)
    max_iterations: int = param(20, 'Newton iterations per plant update at most', low=1,
                                high=1000)
    frame_id: str = param('cbha_base', 'frame_id of the published tip')
    diagnostics_period: float = param(1.0, 'period of /diagnostics [s]', low=0.05, high=60.0)
    log_throttle: float = param(1.0, 'least time between two logs of rejected commands [s]',
                                low=0.0, high=3600.0, live=True)
    on_controller_loss: str = param('vent', 'when a command stream stops for '
                                    'controller_loss_timeout: vent (valves to their lower bound, '
                                    '0 Pa, through the valve model) or hold the last set-point',
                                    choices=ACTIONS, live=True)
    controller_loss_timeout: float = param(0.5, 'a command stream silent this long is a lost '
                                           'controller [s] (steady clock)', low=0.001,
                                           high=3600.0, live=True)
    stop_after_wrong_length: int = param(10, 'this many commands in a row of one wrong length '
                                         '(a controller on another scene) stop the simulator '
                                         '(exit 2); 0: reject them one by one', low=0,
                                         high=1000000, live=True)
    tip_output: str = param('point', 'tip feedback: tip/measured points, rendered stereo '
                            'images, both, or none (a camera-less arm; tip/true stays)',
                            choices=('point', 'stereo', 'both', 'none'))
    payload_mass: float = param(0.0, 'plant payload at the tip, unknown to the controller [kg]',
                                low=0.0, high=10.0)
    wrench_frames: tuple = param(None, 'frames (tip or an index i) whose wrench/tip or '
                                 'wrench/frame_<i> topic (geometry_msgs/WrenchStamped, '
                                 "frame_id: cbha_base or the frame's cbha_frame_<i>) loads the "
                                 'plant (unset: none; docs/loads.md)', unset_type='string_array')
    string_pot_offset: tuple = param(None, 'plant string-pot offsets [reading] (1 or one per '
                                     'pot; unset: those of the scene)',
                                     unset_type='double_array')
    string_pot_gain: tuple = param(None, 'plant string-pot gains [reading/m] (1 or one per pot; '
                                   'unset: those of the scene)', unset_type='double_array')
    string_pot_noise_std: float = param(0.0001, 'string-pot length noise [m]', low=0.0,
                                        high=0.01)
    string_pot_rate_hz: float = param(100.0, 'string_pots publication rate [Hz] (a scene with '
                                      'sensors; at most rate_hz: published in the tick)',
                                      low=0.1, high=1000.0)
    string_pot_stuck: int = param(-1, 'fault: index of the pot (string_pots order) whose '
                                  'reading freezes, -1: none', low=-1, high=63)
    string_pot_stuck_after: float = param(0.0, 'fault: the stuck pot freezes this long after '
                                          'the first accepted pressure_command [s]', low=0.0,
                                          high=1.0e6)
    valve_stuck: int = param(-1, 'fault: index of the valve (valve_names order) stuck shut at '
                             'its vent set-point whatever it is commanded, -1: none', low=-1,
                             high=63, live=True)
    camera_rig: str = param('cameras/rig.yaml', 'stereo output: rig file (a path, or relative '
                            'to config/)')
    camera_rate_hz: float = param(30.0, 'stereo output: frame rate [Hz]', low=0.1, high=1000.0)
    marker_radius: float = param(0.006, 'stereo output: radius of the tip sphere [m]',
                                 low=0.0005, high=0.1)
    contact_stiffness: float = param(1.0e4, "penalty stiffness of the plant's contacts with "
                                     'obstacles [N/m]: a contact force F penetrates F / '
                                     'contact_stiffness', low=1.0, high=1.0e9)
    contact_arrow_scale: float = param(0.05, 'length of a contact force arrow on '
                                       'contacts/markers per newton [m/N]', low=0.0, high=10.0,
                                       live=True)

    def __post_init__(self):
        """Check the plant gravity (3 finite numbers)."""
        finite_triple('gravity', self.gravity)


class CbhaSimNode(Node):
    """
    The simulated robot: pressure command in, tip position out.

    Parameters
    ----------
    on_stop : callable
        Called once the simulator stopped itself (a run of wrong-length commands: its timers
        are cancelled, commands ignored, the reason logged and in ``stopped``); the process of
        :func:`main` ends there with exit 2.
    **kwargs
        Passed to ``rclpy.node.Node``.

    Raises
    ------
    ParameterError
        On invalid parameters or a scene that does not fit them.

    """

    def __init__(self, on_stop=lambda: None, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        self.on_stop = on_stop
        try:
            self.params = declare_parameters(self, CbhaSimParams, self._apply_parameters)
            p = self.params
            nominal = load_scene(p.scene)
            self.valve_names, self.order = valve_order(nominal.actuator_names, p.valve_names)
            errors = plant_errors(nominal.section_names, self.valve_names,
                                  p.section_stiffness_scale, p.cavity_gain_scale, p.base_offset)
            errors = errors.combined(Calibration(tip_payload_mass=p.payload_mass))
            self.scene = load_scene(p.scene, stiffness_scale=p.stiffness_scale,
                                    gravity=p.gravity, calibration=errors)
            self.pots = (None if self.scene.sensors is None else SimulatedPots(
                self.scene.sensors, p.string_pot_offset, p.string_pot_gain,
                p.string_pot_noise_std, p.seed,
                stuck_pot=None if p.string_pot_stuck < 0 else p.string_pot_stuck))
            wrench_frames(p.wrench_frames, self.scene.model.n_links)
        except (ValueError, FileNotFoundError, KeyError) as exc:
            self.destroy_node()
            raise ParameterError(str(exc)) from None
        self.arm = SimulatedArm(self.scene, self.order, latency=p.latency,
                                valve_time_constant=p.valve_time_constant,
                                tip_noise=p.noise_std, pressure_noise=p.pressure_noise_std,
                                seed=p.seed, tolerance=p.tolerance,
                                max_iterations=p.max_iterations,
                                contact_stiffness=p.contact_stiffness,
                                command_kind=p.command_kind)
        self.log = ThrottledLog(self.get_logger(), lambda: self.params.log_throttle)
        self.rejected = Rejections(self.log)
        self.accepted = 0
        self.first_command_time = None
        self.last_result = None
        self.last_stamp = None
        self.not_converged = 0
        self.unconverged_since = None   # steady time of the first unconverged update in a row
        self.failures = 0
        self.resets = 0
        if p.command_kind == 'displacement':
            # a drive's safe state: back to the cables' lengths as built; a command may pull a
            # cable in or let it out by up to half its shortest rest length
            self.command_topic = 'tendon_displacement_command'
            self.vent_command = np.zeros(len(self.order))
            self.command_reach = 0.5 * float(self.arm.plant.drives.rest_lengths.min())
        else:
            self.command_topic = 'pressure_command'
            self.vent_command = command_bounds(self.scene.lower_bounds[self.order],
                                               self.scene.upper_bounds[self.order])[0]
            self.command_reach = None
        # controller loss: a stream of commands (two within the timeout) that stops
        self.command_watch = StalenessWatch(p.controller_loss_timeout)
        self.controller = 'none'    # none (no stream yet), streaming, lost
        self.losses = 0
        self.wrong_length_run = (None, 0)   # (length, count) of the wrong lengths in a row
        self.wrong_length_detail = ''
        self.stopped = None     # why the simulator stopped itself (a run of wrong lengths)
        self.tick_times = TimingStats()
        self.measured_publisher = self.create_publisher(PointStamped, 'tip/measured',
                                                        MEASURED_QOS)
        self.truth_publisher = self.create_publisher(PointStamped, 'tip/true', MEASURED_QOS)
        self.pressure_publisher = self.create_publisher(Float64MultiArray, 'pressure_measured',
                                                        MEASURED_QOS)
        self.create_subscription(Float64MultiArray, self.command_topic, self._on_command,
                                 COMMAND_QOS)
        self.wrenches = WrenchInputs(
            self, p.wrench_frames, self.scene.model.n_links, self.scene.loads, p.frame_id,
            self.arm.plant.set_loads,
            lambda reason, detail: self.rejected.count(f'wrench.{reason}',
                                                       f'rejected wrench: {detail}'))
        self.create_service(Trigger, '~/reset', self._on_reset)
        self._start_obstacles()
        self.timer = self.create_timer(1.0 / p.rate_hz, self._tick)
        self.loss_timer = self.create_timer(LOSS_WATCH_PERIOD, self._watch_controller,
                                            clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.cameras = None
        if p.tip_output in ('stereo', 'both'):
            self.cameras = self._start_cameras()
        if self.pots is not None:
            self.pots_publisher = self.create_publisher(JointState, 'string_pots', MEASURED_QOS)
        self.pots_due = -math.inf
        self.diagnostics = DiagnosticsPublisher(self, self._statuses, p.diagnostics_period)
        self.get_logger().info(
            f'plant {self.scene.name} x{p.stiffness_scale:g} stiffness (sections '
            f'{list(p.section_stiffness_scale)}, cavity gains {list(p.cavity_gain_scale)}, '
            f'base offset {[v * 1e3 for v in p.base_offset]} mm), gravity '
            f'{list(p.gravity)}, valves {p.valve_time_constant * 1e3:g} ms, latency '
            f'{p.latency * 1e3:g} ms, noise {p.noise_std * 1e3:g} mm and '
            f'{p.pressure_noise_std:g} Pa, {p.rate_hz:g} Hz; a command stream silent '
            f'{p.controller_loss_timeout:g} s -> {p.on_controller_loss}')

    def _apply_parameters(self, old, new):
        """Apply a change of the live parameters (checked by :func:`declare_parameters`)."""
        self.arm.valves.latency = new.latency
        self.arm.valves.time_constant = new.valve_time_constant
        self.arm.tip_noise, self.arm.pressure_noise = new.noise_std, new.pressure_noise_std
        self.timer.timer_period_ns = int(round(1e9 / new.rate_hz))
        self.command_watch.timeout = new.controller_loss_timeout
        self.params = new

    def _start_obstacles(self):
        """Create the obstacle and contact topics; draw the scene's obstacles."""
        self.obstacle_updates = 0
        self.contacts_drawn = False
        self.lowest_clearance = math.inf
        self.obstacle_tf = make_broadcaster(self, static=True)
        self.obstacle_publisher = self.create_publisher(MarkerArray, 'obstacle_markers',
                                                        OBSTACLE_MARKERS_QOS)
        self.contact_publisher = self.create_publisher(Float64MultiArray, 'contacts',
                                                       MEASURED_QOS)
        self.contact_marker_publisher = self.create_publisher(MarkerArray, 'contacts/markers',
                                                              MARKER_QOS)
        self.contact_force_publisher = self.create_publisher(WrenchStamped, 'tip/contact_force',
                                                             MEASURED_QOS)
        self.create_subscription(MarkerArray, 'obstacles', self._on_obstacles, OBSTACLES_QOS)
        self._publish_obstacles()

    def _publish_obstacles(self):
        """Draw the plant's obstacles and send their frames (the whole set replaces the last)."""
        self.obstacle_publisher.publish(obstacle_markers(
            self.arm.plant.obstacles, self.get_clock().now().to_msg(), self.params.frame_id))
        if self.obstacle_tf is not None:
            self.obstacle_tf.send(self.params.frame_id, *obstacle_poses(self.arm.plant.obstacles))

    def _on_obstacles(self, message):
        """Replace the plant's obstacles by those of an ``obstacles`` message, or reject it."""
        obstacles, key, detail = obstacles_from_markers(message, self.params.frame_id)
        if obstacles is not None:
            try:
                self.arm.plant.set_obstacles(obstacles)
            except ValueError as exc:
                key, detail = 'no_collision', str(exc)
        if key is not None:
            self.rejected.count(f'obstacles.{key}', f'rejected obstacles: {detail}')
            return
        self.obstacle_updates += 1
        self.get_logger().info(f'obstacles from the obstacles topic: '
                               f'{", ".join(o.name for o in obstacles) or "none"}')
        self._publish_obstacles()

    def _publish_contacts(self, stamp):
        """Publish this tick's contacts (numbers always, arrows while there are any)."""
        contacts = self.arm.plant.contacts
        self.contact_publisher.publish(contact_array(contacts))
        # the tip's (the last effector's, as tip/true) sphere: what a touching tip presses with
        wrench = WrenchStamped()
        wrench.header.stamp, wrench.header.frame_id = stamp, self.params.frame_id
        wrench.wrench.force.x, wrench.wrench.force.y, wrench.wrench.force.z = (
            frame_contact_force(contacts, int(self.arm.plant.effectors.frames[-1])).tolist())
        self.contact_force_publisher.publish(wrench)
        if contacts.frames.size or self.contacts_drawn:
            self.contact_marker_publisher.publish(contact_markers(
                contacts, stamp, self.params.frame_id, self.params.contact_arrow_scale))
        self.contacts_drawn = bool(contacts.frames.size)

    def _start_cameras(self):
        from cbha_inverse.paths import config_path
        from cbha_inverse.ros.common.sim_cameras import SimulatedCameras
        from cbha_inverse.vision.rig import load_rig
        p = self.params
        installed = config_path(p.camera_rig)
        try:
            rig = load_rig(installed if installed.is_file() else p.camera_rig)
        except ValueError as exc:
            self.destroy_node()
            raise ParameterError(str(exc)) from None

        def shape():
            result, stamp = self.last_result, self.last_stamp
            if result is None:
                return None
            return result.effector_positions[-1], result.positions, stamp

        return SimulatedCameras(self, rig, p.camera_rate_hz, p.marker_radius, p.seed, shape)

    def _on_command(self, message):
        if self.stopped is not None:
            return
        values = command_array(message)
        if self.command_reach is None:
            check = check_command(values, len(self.order), self.params.max_pressure)
        else:
            check = check_displacement_command(values, len(self.order), self.command_reach)
        if check.reason == 'wrong_length':
            self._count_wrong_length(len(values), check.detail)
            return
        self._end_wrong_length_run()
        if not check.ok:
            self.rejected.count(check.reason, f'rejected {self.command_topic}: {check.detail}')
            return
        now = self._node_seconds()
        stuck = self.params.valve_stuck
        if 0 <= stuck < len(values):
            values = values.copy()
            values[stuck] = self.vent_command[stuck]
        self.arm.send(now, values)
        self.accepted += 1
        if self.first_command_time is None:
            self.first_command_time = now
        self._mark_command(time.monotonic())

    def _count_wrong_length(self, length, detail):
        """Count a command of the wrong length; stop on a run of them (another scene's)."""
        run_length, run = self.wrong_length_run
        if length != run_length:
            self._end_wrong_length_run()
            run = 0
        self.wrong_length_run = (length, run + 1)
        self.wrong_length_detail = detail
        # counted now, logged when the run ends: a run that stops the node gives one line
        self.rejected.count('wrong_length', None)
        limit = self.params.stop_after_wrong_length
        if limit and run + 1 >= limit and self.stopped is None:
            self.stopped = (
                f'stopping: {run + 1} {self.command_topic} messages in a row have {length} '
                f'values, '
                f'expected {len(self.order)} (the valves of scene {self.scene.name}): the '
                'controller and the simulator probably loaded different scenes; give both the '
                'same scene')
            for timer in (self.timer, self.loss_timer):
                timer.cancel()
            self.get_logger().error(self.stopped)
            self.on_stop()

    def _end_wrong_length_run(self):
        """Log the wrong-length commands of a run that ended (throttled, as every rejection)."""
        run = self.wrong_length_run[1]
        if run:
            self.rejected.log.warning('wrong_length', f'rejected {self.command_topic}: '
                                      f'{self.wrong_length_detail} ({run} in a row, total '
                                      f'{self.rejected["wrong_length"]})')
        self.wrong_length_run = (None, 0)

    def _mark_command(self, now):
        """Record a valid command at steady time ``now``: two within the timeout are a stream."""
        if self.controller == 'lost':
            self.get_logger().info(f'{self.command_topic} arrives again: following it')
            self.controller = 'none'
        if not self.command_watch.stale(now):
            self.controller = 'streaming'
        self.command_watch.mark(now)

    def _watch_controller(self):
        """Steady clock: a stream silent for ``controller_loss_timeout`` vents or holds."""
        now = time.monotonic()
        if self.controller != 'streaming' or not self.command_watch.stale(now):
            return
        self.controller = 'lost'
        self.losses += 1
        action = self.params.on_controller_loss
        if action == 'vent':
            self.arm.send(self._node_seconds(), self.vent_command)
        self.get_logger().warning(
            f'no {self.command_topic} for {self.command_watch.age(now):.2f} s (controller lost): '
            + ('venting, valves to their lower bound' if action == 'vent'
               else 'holding the last set-point'))

    @property
    def pressures(self):
        """(m,) ndarray [Pa]: the valve pressures of the last tick, scene actuator order."""
        return self.arm.pressures

    def _node_seconds(self):
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_reset(self, request, response):
        """``~/reset``: plant at rest, valves vented, pending commands dropped."""
        self.arm.reset()
        self.controller = 'none'
        self.last_result = None
        self.pots_due = -math.inf
        self.first_command_time = None
        self.lowest_clearance = math.inf
        if self.pots is not None:
            self.pots.unstick()
        self.resets += 1
        response.success = True
        response.message = 'plant at rest, valves at 0 Pa'
        self.get_logger().info(response.message)
        return response

    def _tick(self):
        start = time.perf_counter()
        # node clock (use_sim_time: /clock); a clock that jumps back (a looped bag) is a pause
        measured = self.arm.advance(self._node_seconds())
        self.pressure_publisher.publish(command_message(measured, self.valve_names))
        try:
            result, noisy = self.arm.update_plant()
        except (ValueError, ArithmeticError, RuntimeError) as exc:
            self.failures += 1
            self.log.error('plant_update', f'plant update failed, state kept: {exc!r}')
            return
        stamp = self.get_clock().now().to_msg()
        self.last_result, self.last_stamp = result, stamp
        if not result.converged:
            # a state the static solve did not reach is no measurement of the plant: nothing
            # is published until it converges again (logged once per episode)
            self.not_converged += 1
            if self.unconverged_since is None:
                self.unconverged_since = time.monotonic()
                self.get_logger().warning(
                    f'plant static solve did not converge ({result.message}): no tip or pot '
                    'readings published until it does')
            return
        if self.unconverged_since is not None:
            self.get_logger().info(f'plant static solve converged again after '
                                   f'{time.monotonic() - self.unconverged_since:.2f} s')
            self.unconverged_since = None
        tip = result.effector_positions[-1]
        if self.params.tip_output in ('point', 'both'):
            self.measured_publisher.publish(point_stamped(noisy, stamp, self.params.frame_id))
        self.truth_publisher.publish(point_stamped(tip, stamp, self.params.frame_id))
        self.lowest_clearance = min(self.lowest_clearance, self.arm.plant.clearance)
        self._publish_contacts(stamp)
        if self.pots is not None:
            self._publish_pots(result, stamp)
        self.tick_times.add(time.perf_counter() - start)

    def _publish_pots(self, result, stamp):
        """Publish the pots of this tick's state when a reading is due (``string_pot_rate_hz``)."""
        p = self.params
        now, period = stamp.sec + stamp.nanosec * 1e-9, 1.0 / p.string_pot_rate_hz
        if now < self.pots_due <= now + period:  # (a clock that jumped back: due now)
            return
        # half a tick early: tick jitter does not drop a reading at rates up to the tick rate
        self.pots_due = now + period - 0.5 / p.rate_hz
        stuck = (self.first_command_time is not None
                 and now - self.first_command_time >= p.string_pot_stuck_after)
        self.pots_publisher.publish(joint_state(
            self.pots.names, self.pots.read(result.positions, result.rotations, stuck), stamp,
            p.frame_id))

    def _statuses(self):
        result = self.last_result
        total = self.rejected.total
        values = {'accepted_commands': self.accepted, 'resets': self.resets,
                  'controller': self.controller, 'controller_losses': self.losses,
                  'on_controller_loss': self.params.on_controller_loss,
                  'command_age_s': self.command_watch.age(time.monotonic()),
                  **self.rejected.key_values(),
                  'valve_pressures_pa': ' '.join(f'{v:.0f}' for v in self.pressures[self.order]),
                  'newton_iterations': result.iterations if result else 0,
                  'residual_norm': result.residual_norm if result else math.nan,
                  'not_converged_updates': self.not_converged, 'failed_updates': self.failures,
                  **self.tick_times.summary('tick'),
                  'camera_frames': self.cameras.frames if self.cameras else 0,
                  'obstacles': len(self.arm.plant.obstacles),
                  'obstacle_updates': self.obstacle_updates,
                  'contacts': self.arm.plant.contacts.frames.size,
                  'max_penetration_m': float(self.arm.plant.contacts.penetrations.max(
                      initial=0.0)),
                  'min_clearance_m': self.arm.plant.clearance,
                  'lowest_clearance_m': self.lowest_clearance}
        level = WARN if total or (result is not None and not result.converged) else OK
        message = (f'{total} rejected messages' if total else
                   'plant not converged: no tip or pot readings published' if level == WARN
                   else 'ok')
        if self.controller == 'lost':
            level, message = WARN, f'controller lost ({self.params.on_controller_loss})'
        return [make_status(self.get_name(), 'plant', level, message, values)]


class CbhaSimProcess(CbhaSimNode):
    """The simulated robot: pressure command in, tip position out (its process ends on a stop)."""

    def __init__(self, **kwargs):
        super().__init__(on_stop=lambda: end_process(CONFIG_ERROR_EXIT), **kwargs)


def main(argv=None):
    """
    Run the ``cbha_sim`` node until SIGINT/SIGTERM.

    Parameters
    ----------
    argv : list of str, optional
        Command line (default ``sys.argv``), e.g. ``['cbha_sim', '--ros-args',
        '--params-file', 'config/cbha_sim.yaml', '-r', '__ns:=/cbha']``.

    Returns
    -------
    int
        0 on a clean shutdown, 2 on invalid parameters or a controller on another scene (the
        process then ends with the one line the node logged).

    """
    return run_node(CbhaSimProcess, NODE_NAME, argv, params_class=CbhaSimParams)


if __name__ == '__main__':
    sys.exit(main())
