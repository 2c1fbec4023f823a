"""
``shape_estimator``: the arm's shape and tip from its string potentiometers (``docs/nodes.md``).

Subscribes ``string_pots`` (sensor_msgs/JointState, raw readings by name, as ``robotino_bridge``
and ``cbha_sim`` publish them) and ``pressure_measured`` (Float64MultiArray, Pa in ``valve_names``
order); every accepted reading runs one update of
:class:`cbha_inverse.estimate.shape.ShapeEstimator` (``docs/proprioception.md``), with the last
pressures received when they are at most ``pressure_timeout`` old (those of the reading's instant:
``robotino_bridge`` and ``cbha_sim`` publish a sample's pressures before its pots, and the
pressures' subscription is created first, so an executor that finds both waiting takes the
pressures first), and publishes the estimated tip on ``tip/estimated`` (PointStamped, ``frame_id``,
the stamp of the pot reading, sensor data QoS), which ``inverse_solver`` closes its loop on with
``feedback_topic: tip/estimated``; with ``payload_std`` and ``section_stiffness_std``, also the
estimated payload on ``payload/estimated`` (Float64, kg) and the sections' stiffness factors on
``sections/estimated`` (Float64MultiArray, one per scene section in chain order), for the solver's
``payload_topic`` and ``section_stiffness_topic``; with ``publish_gains``, the gains of the
effective actuation on ``gains/estimated`` (one per valve, for ``actuator_gain_topic``). A reading
that lacks a pot name, is malformed, non-finite or out of range, or is older than
``reading_timeout`` is rejected, counted by reason and logged (throttled); nothing is published for
it, so readings that stop or go stale stop ``tip/estimated`` and the solver's stale-feedback hold
or vent acts. A pot dropped from the fit (stuck, or many sigma off) is a WARN and ``degraded``.
``backbone_estimated`` (MarkerArray) draws the estimated backbone every ``marker_period``;
``/diagnostics`` reports the residual per pot, the rank, the tip's standard deviation, the
rejections by reason and the time per estimate. The timeouts and ``log_throttle`` are live
(``set_parameters``); the estimator's noise model is fixed at start.
"""

from dataclasses import dataclass
import sys
import time

from cbha_inverse.estimate.shape import EstimatorOptions, ShapeEstimator
from cbha_inverse.robot.safety import valve_order
from cbha_inverse.ros.common.conversions import (backbone_markers, command_array,
                                                 joint_positions, point_stamped, stamp_ns)
from cbha_inverse.ros.common.diagnostics import (DiagnosticsPublisher, make_status, OK,
                                                 TimingStats, WARN)
from cbha_inverse.ros.common.params import declare_parameters, param, ParameterError
from cbha_inverse.ros.common.qos import MARKER_QOS, MEASURED_QOS
from cbha_inverse.ros.common.rejections import Rejections, ThrottledLog
from cbha_inverse.ros.common.runner import run_node
from cbha_inverse.scene import load_scene
from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray
from visualization_msgs.msg import MarkerArray

NODE_NAME = 'shape_estimator'
# the estimator's option defaults, the node's where it declares no other
_DEFAULTS = EstimatorOptions()


@dataclass(frozen=True)
class ShapeEstimatorParams:
    """
    Parameters of ``shape_estimator`` (``config/shape_estimator.yaml``).

    The estimator's options default to :class:`EstimatorOptions`' own, but for two the node
    tuned on the ROS loop (``docs/proprioception.md``): ``offset_walk_std`` 3 Pa (10 Pa offline)
    and ``weight_std`` 0.01 kg (none offline); the offline numbers and tests keep the
    dataclass's.
    """

    scene: str = param('cbha.yaml', 'scene YAML with a sensors block: a file path, or a name in '
                       'config/scenes')
    valve_names: tuple = param(None, 'order of pressure_measured: a permutation of the scene '
                               'actuators (unset: the scene order)', unset_type='string_array')
    use_pressures: bool = param(True, 'use pressure_measured as the prior of the actuation')
    pressure_timeout: float = param(0.2, 'pressures older than this are not used [s]',
                                    low=0.001, high=60.0, live=True)
    reading_timeout: float = param(0.5, 'a reading stamped older than this is rejected as stale '
                                   '[s] (0: never)', low=0.0, high=60.0, live=True)
    pressure_std: float = param(_DEFAULTS.pressure_std, 'prior std of the effective actuation '
                                'about the measured pressure [Pa]', low=1.0, high=1.0e6)
    gain_std: float = param(_DEFAULTS.gain_std, 'prior std of the gain of the effective '
                            'actuation about the measured pressure [-]', low=1.0e-6, high=10.0)
    gain_walk_std: float = param(_DEFAULTS.gain_walk_std, 'random walk per update of the gain '
                                 'of the effective actuation about the measured pressure [-]',
                                 low=0.0, high=1.0)
    offset_walk_std: float = param(3.0, 'random walk per update of the offset of the effective '
                                   'actuation about the measured pressure [Pa]', low=0.0,
                                   high=1.0e6)
    actuation_walk_std: float = param(_DEFAULTS.actuation_walk_std, 'random walk of the '
                                      'actuation per update without measured pressures [Pa]',
                                      low=1.0, high=1.0e6)
    predict_pressure_change: float = param(_DEFAULTS.predict_pressure_change, 'an update whose '
                                           'pressures changed by more than this first moves '
                                           'the shape to the equilibrium of the estimate at '
                                           'them [Pa]', low=0.0, high=1.0e6)
    payload_std: float = param(0.0, 'prior std of an unknown tip payload [kg] (0: none); its '
                               'estimate is published on payload/estimated',
                               low=0.0, high=10.0)
    weight_std: float = param(0.01, "prior std of an error of the arm's own weight [kg] (a "
                              'stiffness error sags the arm as a weight error does; 0: none; '
                              'not with payload_std: see payload_weight_std)', low=0.0, high=10.0)
    payload_weight_std: float = param(0.0, "with payload_std: prior std of the arm's own weight "
                                      'error estimated with the payload [kg] (0: none)',
                                      low=0.0, high=10.0)
    section_stiffness_std: float = param(0.0, "prior std of each chain section's relative "
                                         'stiffness error, which scales its links in the '
                                         'estimate (0: none); the factors are published on '
                                         'sections/estimated', low=0.0, high=0.9)
    publish_gains: bool = param(False, 'publish the estimated gains 1 + g of the effective '
                                'actuation about the measured pressures on gains/estimated '
                                '(valve_names order; updates with fresh pressures alone)')
    outlier_sigma: float = param(_DEFAULTS.outlier_sigma, 'a pot this many sigma off is '
                                 'dropped for the update', low=1.0, high=1.0e6)
    stuck_window: int = param(_DEFAULTS.stuck_window, 'updates over which a stuck pot is '
                              'looked for (0: never)', low=0, high=100000)
    frame_id: str = param('cbha_base', 'frame of tip/estimated and the markers')
    marker_period: float = param(0.1, 'period of the estimated backbone markers [s]', low=0.01,
                                 high=60.0)
    diagnostics_period: float = param(1.0, 'period of /diagnostics [s]', low=0.05, high=60.0)
    log_throttle: float = param(1.0, 'least time between two logs of rejected or degraded '
                                'readings [s]', low=0.0, high=3600.0, live=True)


class ShapeEstimatorNode(Node):
    """
    The estimator node: string pots (+ pressures) in, estimated tip out.

    Parameters
    ----------
    **kwargs
        Passed to ``rclpy.node.Node``.

    Raises
    ------
    ParameterError
        On invalid parameters or a scene without sensors.

    """

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        try:
            self.params = declare_parameters(self, ShapeEstimatorParams, self._apply_parameters)
            p = self.params
            self.scene = load_scene(p.scene)
            self.valve_names, self.order = valve_order(self.scene.actuator_names, p.valve_names)
            self.estimator = ShapeEstimator.from_scene(self.scene, EstimatorOptions(
                pressure_std=p.pressure_std, gain_std=p.gain_std, gain_walk_std=p.gain_walk_std,
                offset_walk_std=p.offset_walk_std, actuation_walk_std=p.actuation_walk_std,
                predict_pressure_change=p.predict_pressure_change,
                payload_std=p.payload_std or None,
                weight_std=(p.payload_weight_std if p.payload_std else p.weight_std) or None,
                section_stiffness_std=p.section_stiffness_std or None,
                outlier_sigma=p.outlier_sigma,
                stuck_window=p.stuck_window))
        except (ValueError, FileNotFoundError, KeyError) as exc:
            self.destroy_node()
            raise ParameterError(str(exc)) from None
        self.pot_names = self.scene.sensors.names
        self.estimator.warm_up()
        self.pressures = None
        self.pressure_time = -np.inf
        self.log = ThrottledLog(self.get_logger(), lambda: self.params.log_throttle)
        self.rejected = Rejections(self.log)
        self.published = 0
        self.degraded = 0
        self.last = None
        self.estimate_times = TimingStats()
        self.tip_publisher = self.create_publisher(PointStamped, 'tip/estimated', MEASURED_QOS)
        self.payload_publisher = (self.create_publisher(Float64, 'payload/estimated',
                                                        MEASURED_QOS) if p.payload_std else None)
        # one stiffness factor per scene section, chain order (inverse_solver's
        # section_stiffness_topic)
        self.sections_publisher = (self.create_publisher(
            Float64MultiArray, 'sections/estimated', MEASURED_QOS)
            if p.section_stiffness_std else None)
        self.gains_publisher = (self.create_publisher(
            Float64MultiArray, 'gains/estimated', MEASURED_QOS)
            if p.publish_gains and p.use_pressures else None)
        self.marker_publisher = self.create_publisher(MarkerArray, 'backbone_estimated',
                                                      MARKER_QOS)
        if p.use_pressures:
            # created first: rclpy's wait-set executors run the ready callbacks in the order the
            # subscriptions were created, and a sample's pots paired with the previous sample's
            # pressures (every reading, on a plant spun in the same executor) are a pressure
            # step the pots see before the pressures, which the estimator takes for a gain,
            # offset or weight error (docs/proprioception.md)
            self.create_subscription(Float64MultiArray, 'pressure_measured', self._on_pressures,
                                     MEASURED_QOS)
        self.create_subscription(JointState, 'string_pots', self._on_pots, MEASURED_QOS)
        self.marker_timer = self.create_timer(p.marker_period, self._publish_markers)
        self.diagnostics = DiagnosticsPublisher(self, self._statuses, p.diagnostics_period)
        self.get_logger().info(
            f'scene {self.scene.name}: {len(self.pot_names)} string pots {list(self.pot_names)}'
            f', pressures {"used" if p.use_pressures else "not used"} '
            f'({list(self.valve_names)}); {self.tip_publisher.topic_name}')

    def _apply_parameters(self, old, new):
        """Apply a change of the live parameters (the callbacks read them at every message)."""
        self.params = new

    def _reject(self, reason):
        self.rejected.count(reason.split(':')[0], f'rejected string_pots: {reason}')

    def _on_pressures(self, message):
        values = command_array(message)
        if values.size != self.order.size:
            self.rejected.count('pressures.wrong_length', f'rejected pressures: {values.size} '
                                f'values, expected {self.order.size}')
            return
        in_scene_order = np.empty(self.order.size)
        in_scene_order[self.order] = values
        self.pressures, self.pressure_time = in_scene_order, time.monotonic()

    def _on_pots(self, message):
        p = self.params
        readings = joint_positions(message, self.pot_names)
        if readings is None:
            self._reject(f'wrong_names: need {list(self.pot_names)}, got {list(message.name)}')
            return
        age = (self.get_clock().now().nanoseconds - stamp_ns(message.header.stamp)) * 1e-9
        if p.reading_timeout > 0.0 and age > p.reading_timeout:
            self._reject(f'stale: reading {age:.3f} s old')
            return
        fresh = time.monotonic() - self.pressure_time <= p.pressure_timeout
        estimate = self.estimator.update(readings, self.pressures if fresh else None)
        if estimate.status == 'rejected':
            self._reject(estimate.reason)
            return
        self.estimate_times.add(estimate.seconds)
        self.last = estimate
        if estimate.degraded:
            self.degraded += 1
            self.log.warning('degraded', f'degraded estimate: {estimate.reason}')
        self.tip_publisher.publish(point_stamped(estimate.tip, message.header.stamp,
                                                 p.frame_id))
        if self.payload_publisher is not None:
            self.payload_publisher.publish(Float64(data=estimate.payload))
        if self.gains_publisher is not None and fresh:
            gains = 1.0 + self.estimator.gain_error
            self.gains_publisher.publish(Float64MultiArray(
                data=[float(v) for v in gains[self.order]]))
        if self.sections_publisher is not None:
            self.sections_publisher.publish(Float64MultiArray(
                data=[float(v) for v in estimate.section_stiffness]))
        self.published += 1

    def _publish_markers(self):
        if self.last is not None:
            self.marker_publisher.publish(backbone_markers(
                self.estimator.state.positions, None, self.get_clock().now().to_msg(),
                self.params.frame_id, namespace='backbone_estimated'))

    def _statuses(self):
        last = self.last
        total = self.rejected.total
        values = {'published': self.published, 'degraded_updates': self.degraded,
                  **self.rejected.key_values(),
                  **self.estimate_times.summary('estimate')}
        if last is not None:
            values.update({f'residual_mm.{name}': float(r) * 1e3
                           for name, r in zip(self.pot_names, last.residuals)})
            values.update({'rank': last.rank, 'degraded': last.degraded,
                           'tip_std_mm': last.confidence * 1e3, 'payload_kg': last.payload,
                           'weight_error_kg': last.weight})
            values.update({f'section_stiffness.{name}': float(v) for name, v in
                           zip(self.estimator.section_names, last.section_stiffness)})
        level = WARN if (last is not None and last.degraded) or total else OK
        message = (last.reason if last is not None and last.degraded else
                   f'{total} rejected readings' if total else
                   'ok' if last is not None else 'waiting for string_pots')
        # the node's own name (a launch may rename it): two estimators on one /diagnostics
        return [make_status(self.get_name(), 'estimate', level, message, values)]


def main(argv=None):
    """
    Run the ``shape_estimator`` node until SIGINT/SIGTERM.

    Parameters
    ----------
    argv : list of str, optional
        Command line (default ``sys.argv``).

    Returns
    -------
    int
        0 on a clean shutdown, 2 on invalid parameters.

    """
    return run_node(ShapeEstimatorNode, NODE_NAME, argv, params_class=ShapeEstimatorParams)


if __name__ == '__main__':
    sys.exit(main())
