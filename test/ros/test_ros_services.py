"""
The services of the nodes over real DDS, and what diagnostics report about them.

``inverse_solver``: ``~/enable`` (std_srvs/SetBool) and ``~/reset`` (std_srvs/Trigger);
``cbha_sim``: ``~/reset``.
"""

import time

from cbha_inverse.ros.common.qos import COMMAND_QOS, MEASURED_QOS, TARGET_QOS
from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from cbha_inverse.scene import load_scene
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_helpers import spin_for, spin_until, spinning
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import SetBool, Trigger

SCENE = 'tendon_6f_8c'
MAX_TENSION = 10.0
RATE = 100.0
FIRST_TARGET = (0.117, 0.004, -0.008)
SECOND_TARGET = (0.117, -0.006, -0.002)


def _point(xyz):
    message = PointStamped()
    message.header.frame_id = 'cbha_base'
    message.point.x, message.point.y, message.point.z = (float(v) for v in xyz)
    return message


def _call(executor, client, request):
    """Call a service and spin until the response; return (response, arrival time)."""
    future = client.call_async(request)
    assert spin_until(executor, future.done, 5.0), f'no response from {client.srv_name}'
    return future.result(), time.monotonic()


def _control_values(diagnostics):
    """Return the key/value dicts of every 'inverse_solver: control' status received."""
    return [{v.key: v.value for v in status.values} for array in diagnostics
            for status in array.status if status.name == 'inverse_solver: control']


def test_enable_stops_and_resumes_and_reset_restarts_from_rest(rclpy_context):
    solver = InverseSolverNode(context=rclpy_context, namespace='/cbha', parameter_overrides=[
        Parameter('scene', value=SCENE), Parameter('rate_hz', value=RATE),
        Parameter('max_pressure', value=MAX_TENSION),
        Parameter('diagnostics_period', value=0.1)])
    client = Node('service_client', context=rclpy_context, namespace='/cbha')
    target_pub = client.create_publisher(PointStamped, 'target', TARGET_QOS)
    commands, diagnostics = [], []
    client.create_subscription(Float64MultiArray, 'pressure_command', lambda m: commands.append(
        (time.monotonic(), np.array(m.data))), COMMAND_QOS)
    client.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 50)
    enable = client.create_client(SetBool, 'inverse_solver/enable')
    reset = client.create_client(Trigger, 'inverse_solver/reset')
    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, lambda: enable.service_is_ready() and reset.service_is_ready()
                          and target_pub.get_subscription_count() > 0
                          and solver.command_publisher.get_subscription_count() > 0, 10.0)
        target_pub.publish(_point(FIRST_TARGET))
        assert spin_until(executor, lambda: len(commands) >= 20, 5.0)

        response, _ = _call(executor, enable, SetBool.Request(data=False))
        ticks_when_disabled, held = solver.ticks, solver.command.copy()
        assert response.success and 'disabled' in response.message
        target_pub.publish(_point(SECOND_TARGET))  # becomes the set-point, not solved
        spin_for(executor, 0.4)
        assert spin_until(executor, lambda: any(
            v['enabled'] == 'False' and v['decision'] == 'disabled'
            for v in _control_values(diagnostics)), 2.0)
        disabled_from = len(commands)

        response, _ = _call(executor, reset, Trigger.Request())
        assert response.success and 'rest' in response.message
        spin_for(executor, 0.1)
        # disabled (on_disable: hold): no tick, the last command published again (a controller
        # that falls silent would look lost to the arm)
        assert solver.ticks == ticks_when_disabled
        before_resume = len(commands)
        assert before_resume > disabled_from
        for _, command in commands[disabled_from:]:
            np.testing.assert_array_equal(command, held)
        response, _ = _call(executor, enable, SetBool.Request(data=True))
        assert response.success
        assert spin_until(executor, lambda: len(commands) > before_resume + 5, 5.0)
        assert spin_until(executor, lambda: any(
            v['enabled'] == 'True' and v['resets'] == '1'
            for v in _control_values(diagnostics)), 2.0)
    assert disabled_from >= 20
    # the first command after the reset is the first tick of a solver at rest (a held one
    # may still be on its way when the service returns)
    scene = load_scene(SCENE)
    fresh = scene.make_inverse_solver(newton_steps=1, relinearize_every=1,
                                      qp_solver='active_set')
    expected = np.clip(fresh.step(np.array([SECOND_TARGET])).actuation, 0.0, MAX_TENSION)
    first_after = next(c for _, c in commands[before_resume:] if not np.array_equal(c, held))
    np.testing.assert_allclose(first_after, expected, rtol=1e-9, atol=1e-9 * MAX_TENSION)
    assert not np.allclose(first_after, held, atol=1e-3)


def test_sim_reset_returns_the_plant_to_rest(rclpy_context):
    names = list(load_scene(SCENE).actuator_names)
    sim = CbhaSimNode(context=rclpy_context, namespace='/cbha', parameter_overrides=[
        Parameter('scene', value=SCENE), Parameter('rate_hz', value=RATE),
        Parameter('max_pressure', value=MAX_TENSION), Parameter('noise_std', value=0.0)])
    client = Node('sim_client', context=rclpy_context, namespace='/cbha')
    command_pub = client.create_publisher(Float64MultiArray, 'pressure_command', COMMAND_QOS)
    tips = []
    client.create_subscription(PointStamped, 'tip/true', lambda m: tips.append(
        (time.monotonic(), np.array([m.point.x, m.point.y, m.point.z]))), MEASURED_QOS)
    reset = client.create_client(Trigger, 'cbha_sim/reset')
    rest = load_scene(SCENE, stiffness_scale=0.9, gravity=(0.0, 0.0, -9.81)).forward(
        np.zeros(len(names))).effector_positions[-1]
    pulled = np.zeros(len(names))
    pulled[0] = 0.5 * MAX_TENSION
    with spinning(rclpy_context, sim, client) as executor:
        assert spin_until(executor, lambda: reset.service_is_ready()
                          and command_pub.get_subscription_count() > 0 and tips, 10.0)
        command_pub.publish(Float64MultiArray(data=pulled.tolist()))
        assert spin_until(executor, lambda: np.linalg.norm(tips[-1][1] - rest) > 1e-3, 5.0)
        response, reset_at = _call(executor, reset, Trigger.Request())
        assert response.success
        assert spin_until(executor, lambda: sum(t > reset_at + 0.05 for t, _ in tips) >= 3, 5.0)
    assert sim.resets == 1
    after = [tip for t, tip in tips if t > reset_at + 0.05]
    np.testing.assert_allclose(after[-1], rest, atol=1e-6)
