"""
Paths of the controller that no other test takes.

Newton steps per tick, the QP fallback, the ``timer`` trigger, measurement-to-target matching
by stamp, and the node's handling of a solver that raises, returns non-finite pressures or fails
to linearise (real nodes over real DDS; the failures are injected into the node's own solver
object).
"""

import contextlib
import math
import time

from cbha_inverse.core.inverse.qp import ProxsuiteQP
from cbha_inverse.ros.common.qos import COMMAND_QOS, MEASURED_QOS, TARGET_QOS
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from cbha_inverse.scene import load_scene
from geometry_msgs.msg import PointStamped
import numpy as np
import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_helpers import spin_for, spin_until
from std_msgs.msg import Float64MultiArray

SCENE = 'tendon_6f_8c'
CENTER = np.array([0.117, 0.0, -0.005])


def _target():
    scene = load_scene(SCENE)
    target = scene.rest_effector_positions.copy()
    target[-1] += [0.0, 0.01, 0.005]
    return scene, target


@pytest.mark.parametrize('steps', [1, 3])
def test_newton_steps_bring_the_model_to_the_static_equilibrium(steps):
    """After one tick the model state vs the scene's static solve of the commanded actuation."""
    scene, target = _target()
    result = scene.make_inverse_solver(newton_steps=steps).step(target)
    static = scene.forward(result.actuation)
    error = np.abs(result.effector_positions - static.effector_positions).max()
    print(f'{steps} Newton step(s): model tip {error:.2e} m from the static equilibrium')
    # one step leaves the linearisation error (~0.5 mm here); Newton converges quadratically
    assert error < (1e-3 if steps == 1 else 1e-7)
    assert steps == 1 or error < 1e-4 * np.abs(static.effector_positions
                                               - scene.rest_effector_positions).max()


def test_a_caller_editing_the_result_does_not_change_the_solver():
    """TickResult.actuation is the caller's copy: editing it leaves the next ticks unchanged."""
    scene, target = _target()
    edited, untouched = scene.make_inverse_solver(), scene.make_inverse_solver()
    first = edited.step(target)
    assert np.array_equal(first.actuation, untouched.step(target).actuation)
    first.actuation[:] = np.nan
    assert np.all(np.isfinite(edited.actuation))
    for _ in range(3):
        assert np.array_equal(edited.step(target).actuation, untouched.step(target).actuation)


def test_proxsuite_failure_falls_back_to_gauss_seidel():
    """A proxsuite limited to one iteration fails: the tick reports qp_fallback, never NaN."""
    scene, target = _target()
    solver = scene.make_inverse_solver(qp_solver='proxsuite')
    solver._qp = ProxsuiteQP(len(scene.actuator_names), max_iterations=1)
    result = solver.step(target)
    assert result.status == 'qp_fallback'
    assert result.qp_status in ('gauss_seidel_converged', 'gauss_seidel_max_iterations')
    assert np.all(np.isfinite(result.actuation))
    assert np.all(result.actuation >= solver.lower_bounds)
    assert np.all(result.actuation <= solver.upper_bounds)
    # Gauss-Seidel still moves the predicted tip toward the target (rest is 11 mm away)
    assert result.predicted_error < 0.5 * np.linalg.norm(target[-1]
                                                         - scene.rest_effector_positions[-1])


def _solver_node(context, **params):
    names = list(load_scene(SCENE).actuator_names)
    params = {'scene': SCENE, 'valve_names': names, 'max_pressure': 10.0, **params}
    return InverseSolverNode(context=context, namespace='/cbha', parameter_overrides=[
        Parameter(k, value=v) for k, v in params.items()])


@contextlib.contextmanager
def _running(context, solver):
    """Yield (executor, client, target publisher, measured publisher, received commands)."""
    client = Node('client', context=context, namespace='/cbha')
    target_pub = client.create_publisher(PointStamped, 'target', TARGET_QOS)
    measured_pub = client.create_publisher(PointStamped, 'tip/measured', MEASURED_QOS)
    commands = []
    client.create_subscription(Float64MultiArray, 'pressure_command',
                               lambda m: commands.append(np.array(m.data)), COMMAND_QOS)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(solver)
    executor.add_node(client)
    try:
        assert spin_until(executor, lambda: target_pub.get_subscription_count() > 0
                          and measured_pub.get_subscription_count() > 0, 10.0)
        yield executor, client, target_pub, measured_pub, commands
    finally:
        executor.shutdown()
        solver.destroy_node()
        client.destroy_node()


def _point(point, stamp_ns=0):
    message = PointStamped()
    message.header.frame_id = 'cbha_base'
    message.header.stamp.sec, message.header.stamp.nanosec = divmod(int(stamp_ns), 10 ** 9)
    message.point.x, message.point.y, message.point.z = (float(v) for v in point)
    return message


@pytest.mark.parametrize('trigger', ['target', 'timer'])
def test_target_trigger_solves_each_target_timer_trigger_per_period(rclpy_context, trigger):
    """A burst of 20 targets: 20 ticks when triggered by targets, one per period at 5 Hz."""
    period_s = 0.2
    solver = _solver_node(rclpy_context, trigger=trigger, rate_hz=1.0 / period_s)
    with _running(rclpy_context, solver) as (executor, _, target_pub, _, _):
        start = time.monotonic()
        for i in range(20):
            target_pub.publish(_point(CENTER + [0.0, 0.0005 * i, 0.0]))
            spin_for(executor, 0.005)
        assert spin_until(executor, lambda: solver.ticks >= (20 if trigger == 'target' else 1),
                          10.0)
        spin_for(executor, 0.05)
        ticks = solver.ticks
        elapsed_s = time.monotonic() - start
    if trigger == 'target':
        assert ticks == 20
    else:
        # the timer ticks once per period that passed, whatever the load (under coverage without
        # the compiled kernels the burst alone can take longer than a period)
        assert 1 <= ticks <= int(elapsed_s / period_s) + 1
        assert elapsed_s < 20 * period_s, 'the burst was too slow to tell the triggers apart'


def test_measurement_is_compared_with_the_target_of_its_stamp(rclpy_context):
    """Closed loop: a measurement equal to the target of its stamp adds no correction."""
    solver = _solver_node(rclpy_context, mode='closed', loop_gain=0.5, rate_hz=1.0)
    first, second = CENTER + [0.0, 0.004, 0.0], CENTER + [0.0, -0.004, 0.0]
    with _running(rclpy_context, solver) as (executor, _, target_pub, measured_pub, _):
        target_pub.publish(_point(first, 1_000_000_000))
        target_pub.publish(_point(second, 2_000_000_000))
        assert spin_until(executor, lambda: len(solver.target_history) == 2, 5.0)
        measured_pub.publish(_point(first, 1_500_000_000))  # between the two target stamps
        assert spin_until(executor, lambda: not math.isnan(solver.target_error), 5.0)
        matched_error = solver.target_error
        matched_correction = solver.corrector.correction.copy()
        # a stamp after the history: compared with the current target (8 mm away)
        measured_pub.publish(_point(first, 3_000_000_000))
        assert spin_until(executor, lambda: solver.target_error > 0.0, 5.0)
    assert matched_error == 0.0
    np.testing.assert_array_equal(matched_correction, 0.0)
    assert solver.target_error == pytest.approx(0.008, abs=1e-12)
    # the integral moves the goal by gain * (target - measured) = 0.5 * (second - first)
    np.testing.assert_allclose(solver.corrector.correction, [[0.0, -0.004, 0.0]], atol=1e-12)


@pytest.mark.parametrize('failure', ['raises', 'non_finite', 'prepare_raises'])
def test_solver_failures_hold_the_last_command_and_are_counted(rclpy_context, failure):
    solver = _solver_node(rclpy_context, rate_hz=1.0)
    with _running(rclpy_context, solver) as (executor, _, target_pub, _, commands):
        target_pub.publish(_point(CENTER + [0.0, 0.005, 0.0]))
        assert spin_until(executor, lambda: solver.ticks == 1 and commands, 5.0)
        spin_for(executor, 0.05)
        good = solver.command.copy()
        assert np.any(good > 0.0)
        step, prepare = solver.solver.step, solver.solver.prepare

        def failing_step(goal):
            if failure == 'raises':
                raise ArithmeticError('injected')
            result = step(goal)
            if failure == 'non_finite':
                # a copy: the solver's own state stays finite
                result = result._replace(actuation=np.full_like(result.actuation, math.nan))
            return result

        def failing_prepare():
            raise RuntimeError('injected')

        solver.solver.step = failing_step
        if failure == 'prepare_raises':
            solver.solver.prepare = failing_prepare
        before = len(commands)
        target_pub.publish(_point(CENTER + [0.0, -0.005, 0.0]))
        assert spin_until(executor, lambda: len(commands) > before, 5.0)
        spin_for(executor, 0.05)
        solver.solver.step, solver.solver.prepare = step, prepare
        after_failure = commands[-1]
        target_pub.publish(_point(CENTER + [0.0, -0.005, 0.0]))
        assert spin_until(executor, lambda: len(commands) > before + 1, 5.0)
        recovered = commands[-1]
    assert np.all(np.isfinite(np.array(commands)))
    if failure == 'raises':
        assert solver.statuses['exception'] == 1
        np.testing.assert_array_equal(after_failure, good)
    elif failure == 'non_finite':
        assert solver.rejected['solver.non_finite'] == 1
        np.testing.assert_array_equal(after_failure, good)
    else:
        # the tick itself succeeded (a new command), only the linearisation after it failed
        assert solver.statuses['exception'] == 1
        assert not np.array_equal(after_failure, good)
    # the next tick works again and moves on
    assert not np.array_equal(recovered, good)
