"""
Touch with a bounded force over real DDS: ``inverse_solver``'s ``touch``, ``cbha_sim``'s force.

Both nodes run ``cbha_table`` with a wall in front of the tip (an ``obstacles`` message: a thin
CUBE); a PoseStamped on ``touch`` (the contact point on the wall, its z axis the wall's normal
-x) makes the tip press the wall; ``cbha_sim``'s ``tip/contact_force`` measures the force
within ``touch_force_bounds``. A pose with a zero quaternion is rejected and counted, the touch
kept; ``~/release_touch`` ends it.
"""

from cbha_inverse.ros.common.qos import MEASURED_QOS, OBSTACLES_QOS, TARGET_QOS
from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from cbha_inverse.scene import load_scene
from geometry_msgs.msg import PoseStamped, WrenchStamped
import numpy as np
from rclpy.node import Node
from ros_helpers import assert_refused, make_node, set_parameters, spin_until, spinning
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker, MarkerArray

BOUNDS = (0.5, 1.5)
"""The force bounds of the test [N]."""


def _wall(face_x):
    """Return an ``obstacles`` message: a wall 2 cm thick whose face (normal -x) is at x."""
    item = Marker()
    item.header.frame_id = 'cbha_base'
    item.ns, item.id, item.type, item.action = 'lab', 0, Marker.CUBE, Marker.ADD
    item.pose.position.x = face_x + 0.01
    item.pose.orientation.w = 1.0
    item.scale.x, item.scale.y, item.scale.z = 0.02, 1.0, 1.0
    return MarkerArray(markers=[item])


def _touch(point, quaternion):
    """Return a ``touch`` pose at ``point`` [m] with ``quaternion`` (x, y, z, w)."""
    message = PoseStamped()
    message.header.frame_id = 'cbha_base'
    message.pose.position.x, message.pose.position.y, message.pose.position.z = point
    orientation = message.pose.orientation
    orientation.x, orientation.y, orientation.z, orientation.w = quaternion
    return message


def test_the_tip_presses_a_wall_with_a_force_within_the_bounds(rclpy_context):
    scene = load_scene('cbha_table')
    rest = scene.rest_effector_positions[0]
    face = float(rest[0] + scene.collision.radii[-1] + 0.005)
    point = (face, float(rest[1]), float(rest[2]))
    z_to_minus_x = (0.0, -np.sqrt(0.5), 0.0, np.sqrt(0.5))
    solver = make_node(InverseSolverNode, rclpy_context, namespace='/touch', mode='open',
                       scene='cbha_table', touch_force_bounds=list(BOUNDS))
    sim = make_node(CbhaSimNode, rclpy_context, namespace='/touch', scene='cbha_table',
                    noise_std=0.0)
    client = Node('touch_client', context=rclpy_context, namespace='/touch')
    obstacles = client.create_publisher(MarkerArray, 'obstacles', OBSTACLES_QOS)
    touch = client.create_publisher(PoseStamped, 'touch', TARGET_QOS)
    forces = []
    client.create_subscription(WrenchStamped, 'tip/contact_force', forces.append, MEASURED_QOS)
    release = client.create_client(Trigger, 'inverse_solver/release_touch')
    with spinning(rclpy_context, solver, sim, client) as executor:
        assert spin_until(executor, lambda: obstacles.get_subscription_count() >= 2
                          and touch.get_subscription_count() > 0, 10.0)
        obstacles.publish(_wall(face))
        assert spin_until(executor, lambda: solver.obstacle_updates == 1
                          and sim.obstacle_updates == 1, 10.0)
        touch.publish(_touch(point, z_to_minus_x))
        assert spin_until(executor, lambda: solver.ticks > 150 and len(forces) > 150, 20.0)
        predicted = solver.last_result.touch_forces[0]
        measured = -forces[-1].wrench.force.x          # along the wall's normal -x
        touches = solver.solver.touches
        touch.publish(_touch(point, (0.0, 0.0, 0.0, 0.0)))
        assert spin_until(executor, lambda: sum(solver.rejected.values()) == 1, 5.0)
        assert solver.solver.touches.keys() == touches.keys()
        assert spin_until(executor, lambda: release.service_is_ready(), 5.0)
        future = release.call_async(Trigger.Request())
        assert spin_until(executor, future.done, 5.0)
    assert solver.rejected == {'touch.bad_touch': 1}
    np.testing.assert_allclose(touches[0].normal, [-1.0, 0.0, 0.0], atol=1e-12)
    assert abs(predicted - np.mean(BOUNDS)) < 1e-3
    assert BOUNDS[0] <= measured <= BOUNDS[1]
    assert forces[-1].header.frame_id == 'cbha_base'
    assert future.result().success and solver.solver.touches == {}


def test_touch_force_bounds_are_checked_and_apply_to_the_current_touch(rclpy_context):
    """A live change of ``touch_force_bounds``: refused when invalid, else the touch's bounds."""
    solver = make_node(InverseSolverNode, rclpy_context, namespace='/touchp', mode='open',
                       scene='cbha_table')
    solver.solver.set_touch(0, [0.2, 0.0, -0.08], [0.0, 0.0, 1.0], [0.2, 0.4])
    try:
        assert_refused(solver, 'force bounds', touch_force_bounds=[0.5, 0.1])
        assert_refused(solver, 'force bounds', touch_force_bounds=[-0.1, 0.4])
        np.testing.assert_array_equal(solver.solver.touches[0].force_bounds, [0.2, 0.4])
        assert set_parameters(solver, touch_force_bounds=[0.5, 1.0]).successful
        np.testing.assert_array_equal(solver.solver.touches[0].force_bounds, [0.5, 1.0])
    finally:
        solver.destroy_node()
