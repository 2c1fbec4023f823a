"""
Live parameters over real DDS: rclpy's parameter client changes a running node's tuning.

A tuning parameter (``live``) is accepted with the start-up checks and takes effect on the
commands the node publishes; an invalid value is refused with the reason and the old value stays;
a structural parameter (the scene) is refused as read-only.
"""

from cbha_inverse.ros.common.qos import COMMAND_QOS
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from cbha_inverse.scene import load_scene
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from ros_helpers import make_node, spin_until
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
