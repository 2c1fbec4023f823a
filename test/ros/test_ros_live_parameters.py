"""
Live parameters over real DDS: rclpy's parameter client changes a running node's tuning.

A tuning parameter (``live``) is accepted with the start-up checks and takes effect on the
commands the node publishes; an invalid value is refused with the reason and the old value stays;
a structural parameter (the scene) is refused as read-only. The other nodes' live parameters
through rclpy's parameter API in the process (the callback that the parameter service runs).
"""

from cbha_inverse.ros.common.qos import COMMAND_QOS
from cbha_inverse.ros.nodes.cbha_excite import ExciteNode
from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from cbha_inverse.ros.nodes.robotino_bridge import RobotinoBridgeNode
from cbha_inverse.ros.nodes.shape_estimator import ShapeEstimatorNode
from cbha_inverse.ros.nodes.stereo_tracker import StereoTrackerNode
from cbha_inverse.ros.nodes.trajectory import TrajectoryNode
from cbha_inverse.scene import load_scene
import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from ros_helpers import assert_refused, make_node, set_parameters, spin_until
from std_msgs.msg import Float64MultiArray

SCENE = 'tendon_6f_8c'


def _set(executor, client, *parameters):
    future = client.set_parameters(list(parameters))
    assert spin_until(executor, future.done, 20.0), 'no answer from the parameter service'
    return future.result().results


def test_live_parameters_take_effect_and_bad_ones_are_refused_with_a_reason(rclpy_context):
    names = list(load_scene(SCENE).actuator_names)
    solver = make_node(InverseSolverNode, rclpy_context, scene=SCENE, valve_names=names,
                       publish_idle=True, rate_hz=50.0)
    user = Node('parameter_user', context=rclpy_context, namespace='/cbha')
    commands = []
    user.create_subscription(Float64MultiArray, 'pressure_command', commands.append,
                             COMMAND_QOS)
    client = AsyncParameterClient(user, '/cbha/inverse_solver')
    executor = SingleThreadedExecutor(context=rclpy_context)
    executor.add_node(solver)
    executor.add_node(user)
    try:
        assert client.wait_for_services(timeout_sec=20.0)
        # idle: the vent command (0 N) at rate_hz
        assert spin_until(executor, lambda: len(commands) >= 3, 20.0)
        assert all(list(c.data) == [0.0] * len(names) for c in commands)

        [result] = _set(executor, client, Parameter('vent_pressure', value=1.5))
        assert result.successful, result.reason
        commands.clear()
        assert spin_until(executor, lambda: len(commands) >= 3, 20.0)
        assert list(commands[-1].data) == [1.5] * len(names)
        assert solver.get_parameter('vent_pressure').value == 1.5

        # refused by the node's own check (the workspace box), with the reason; nothing changes
        [result] = _set(executor, client, Parameter('workspace_min', value=[0.7, 0.0, 0.0]))
        assert not result.successful
        assert 'must be below' in result.reason, result.reason
        assert list(solver.get_parameter('workspace_min').value) == [-0.3, -0.4, -0.4]
        assert solver.params.workspace_min == (-0.3, -0.4, -0.4)
        # refused by the range of its descriptor
        [result] = _set(executor, client, Parameter('loop_gain', value=2.0))
        assert not result.successful and result.reason, result
        assert solver.params.loop_gain == 0.1
        # a set of changes is refused as a whole when one is bad
        results = _set(executor, client, Parameter('loop_gain', value=0.3),
                       Parameter('stale_action', value='explode'))
        assert not all(r.successful for r in results)
        assert any('must be one of' in r.reason for r in results), results
        # structural: read-only, and it says so
        [result] = _set(executor, client, Parameter('scene', value='cbha'))
        assert not result.successful and 'read-only' in result.reason, result.reason
        assert solver.get_parameter('scene').value == SCENE

        [result] = _set(executor, client, Parameter('loop_gain', value=0.3))
        assert result.successful, result.reason
        assert solver.params.loop_gain == 0.3
        assert solver.get_parameter('loop_gain').value == 0.3
        commands.clear()
        assert spin_until(executor, lambda: len(commands) >= 3, 20.0)
        assert list(commands[-1].data) == [1.5] * len(names)
    finally:
        executor.shutdown()
        solver.destroy_node()
        user.destroy_node()


def _timer_period(node):
    return node.timer.timer_period_ns


# node, its overrides, a live change and what it changes, a refused one and its reason, a
# read-only parameter
NODE_CASES = {
    'trajectory': (TrajectoryNode, {}, {'rate_hz': 20.0, 'wait_for_subscribers': 1},
                   (_timer_period, 50_000_000), ('out of range', {'rate_hz': 0.0}),
                   {'radius': 0.02}),
    'cbha_excite': (ExciteNode, {'scene': SCENE, 'program': 'extension',
                                 'wait_for_subscribers': 5},
                    {'rate_hz': 25.0, 'wait_for_subscribers': 0}, (_timer_period, 40_000_000),
                    ('DOUBLE', {'rate_hz': 25}), {'hold_time': 1.0}),
    'cbha_sim': (CbhaSimNode, {'scene': SCENE}, {'latency': 0.01, 'rate_hz': 50.0},
                 (lambda node: (node.arm.valves.latency, _timer_period(node)), (0.01, 20_000_000)),
                 ('out of range', {'noise_std': 0.5}), {'gravity': [0.0, 0.0, 0.0]}),
    'robotino_bridge': (RobotinoBridgeNode, {}, {'vent_pressure': 2.0e4, 'rate_hz': 20.0},
                        (lambda node: (node.vent_bar[0], _timer_period(node)), (0.2, 50_000_000)),
                        ('above max_pressure', {'max_pressure': 1.0e4}),
                        {'valve_names': ['inner_over']}),
    'shape_estimator': (ShapeEstimatorNode, {}, {'reading_timeout': 0.0,
                                                 'pressure_timeout': 1.0},
                        (lambda node: node.params.pressure_timeout, 1.0),
                        ('out of range', {'pressure_timeout': 0.0}), {'pressure_std': 1.0}),
}


@pytest.mark.parametrize('case', sorted(NODE_CASES))
def test_a_nodes_tuning_is_live_and_its_structure_read_only(rclpy_context, case, request):
    node_class, overrides, change, (effect, expected), (reason, refused), structural = (
        NODE_CASES[case])
    if node_class is RobotinoBridgeNode:
        request.getfixturevalue('robotino_msgs')
    node = make_node(node_class, rclpy_context, **overrides)
    try:
        assert set_parameters(node, **change).successful
        assert effect(node) == expected
        assert all(getattr(node.params, name) == value for name, value in change.items())
        assert_refused(node, reason, **refused)
        assert_refused(node, 'read-only', **structural)
        assert effect(node) == expected
    finally:
        node.destroy_node()


def test_stereo_thresholds_are_live_with_the_start_up_checks(rclpy_context):
    node = make_node(StereoTrackerNode, rclpy_context)
    try:
        assert node.tracker is not None
        assert set_parameters(node, max_depth=1.5, marker__min_area=30.0,
                              max_pair_dt=0.004).successful
        assert node.tracker.limits.max_depth == 1.5 and node.marker.min_area == 30.0
        assert node.tracker.trackers[0].params.min_area == 30.0
        assert node.pairer.max_dt == 0.004
        tracker = node.tracker
        # the node's own checks, as at start: empty ranges, an unknown ArUco dictionary
        assert_refused(node, 'must be below max_depth', min_depth=1.8)
        assert_refused(node, 'above marker.max_area', marker__min_area=3.0e4)
        assert_refused(node, 'unknown ArUco dictionary', marker__kind='aruco',
                       marker__aruco_dictionary='DICT_NONE')
        assert node.tracker is tracker and node.marker.kind == 'sphere'
        assert_refused(node, 'read-only', image_depth=5)
        assert set_parameters(node, log_throttle=5.0).successful
        assert node.tracker is tracker      # a change elsewhere keeps the tracker's state
    finally:
        node.destroy_node()
