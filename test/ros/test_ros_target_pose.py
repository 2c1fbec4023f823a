"""
``target_pose`` over real DDS: a pose target turns an ``axis`` effector (``cbha_approach``).

The target is a pose the plant reaches (the forward model at chosen pressures: the tip's position
and the orientation of its frame); the node takes its position and turns the effector's approach
axis to where that orientation carries it, as its model shows after the ticks. A quaternion far
from unit length and a pose in an unknown frame are refused and counted; neither moves the
orientation target.
"""

from cbha_inverse.core.so3 import quat_from_matrix
from cbha_inverse.ros.common.qos import TARGET_QOS
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from cbha_inverse.scene import load_scene
from geometry_msgs.msg import PoseStamped
import numpy as np
from rclpy.node import Node
from ros_helpers import make_node, spin_for, spin_until, spinning


def _pose(position, quaternion, frame_id='cbha_base'):
    message = PoseStamped()
    message.header.frame_id = frame_id
    p, q = message.pose.position, message.pose.orientation
    p.x, p.y, p.z = (float(v) for v in position)
    q.x, q.y, q.z, q.w = (float(v) for v in quaternion)
    return message


def test_a_pose_target_turns_the_approach_axis(rclpy_context):
    scene = load_scene('cbha_approach')
    reached = scene.forward(np.array([6e4, 1e4, 2e4, 3e4, 5e4, 1e4]), strict=True)
    rotation = reached.state.rotations[scene.effectors.frames[0]]
    position = reached.effector_positions[0]
    direction = rotation @ scene.effectors.axes[0]
    solver = make_node(InverseSolverNode, rclpy_context, scene='cbha_approach', mode='open',
                       trigger='timer')
    client = Node('client', context=rclpy_context, namespace='/cbha')
    poses = client.create_publisher(PoseStamped, 'target_pose', TARGET_QOS)
    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, lambda: poses.get_subscription_count() == 1, 10.0)
        poses.publish(_pose(position, quat_from_matrix(rotation)))
        assert spin_until(executor, lambda: solver.ticks >= 60, 20.0)
        model_direction = solver.solver.effector_directions()[0]
        model_position = solver.solver.effector_positions()[0]
        before = solver.solver.orientation_targets[0].copy()
        poses.publish(_pose(position, 0.5 * quat_from_matrix(rotation)))
        poses.publish(_pose(position, quat_from_matrix(rotation), frame_id='nowhere'))
        assert spin_until(executor, lambda: sum(solver.rejected.values()) == 2, 5.0)
        spin_for(executor, 0.1)
        after = solver.solver.orientation_targets[0]
    angle = np.degrees(np.arccos(np.clip(model_direction @ direction, -1.0, 1.0)))
    assert angle < 1.0, angle
    assert np.linalg.norm(model_position - position) < 0.5e-3
    # the target was not the rest orientation: the axis really turned
    assert np.degrees(np.arccos(direction @ [1.0, 0.0, 0.0])) > 10.0
    np.testing.assert_array_equal(after, before)
    assert set(solver.rejected) == {'target_pose.bad_orientation', 'target_pose.unknown_frame'}
