"""
``inverse_solver``'s obstacles over real DDS: the scene's in its QP, the ``obstacles`` topic's.

With ``cbha_table`` a target below the table is held off by the obstacle rows (the tick reads
``'unreachable'``: the table holds the tip from its target); an ``obstacles`` message (the
carrier and parsing of ``cbha_sim``) replaces the set, a bad one is rejected and counted with
the obstacles kept, an empty one removes every obstacle and with them the rows.
"""

import math

from cbha_inverse.ros.common.obstacle_markers import obstacles_from_markers
from cbha_inverse.ros.common.qos import OBSTACLE_MARKERS_QOS, OBSTACLES_QOS, TARGET_QOS
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from geometry_msgs.msg import PointStamped
from rclpy.node import Node
from ros_helpers import make_node, spin_until, spinning, target_point
from visualization_msgs.msg import Marker, MarkerArray

BELOW_TABLE = (0.2, 0.0, -0.1)
"""A target 20 mm below the table of ``cbha_table`` [m]."""


def _ball(position, diameter=0.02):
    item = Marker()
    item.header.frame_id = 'cbha_base'
    item.ns, item.id, item.type, item.action = 'lab', 0, Marker.SPHERE, Marker.ADD
    item.pose.position.x, item.pose.position.y, item.pose.position.z = position
    item.pose.orientation.w = 1.0
    item.scale.x = item.scale.y = item.scale.z = diameter
    return item


def test_the_solver_keeps_clear_of_its_obstacles_and_takes_new_ones(rclpy_context):
    node = make_node(InverseSolverNode, rclpy_context, mode='open', scene='cbha_table')
    client = Node('obstacle_client', context=rclpy_context, namespace='/cbha')
    target_pub = client.create_publisher(PointStamped, 'target', TARGET_QOS)
    obstacles = client.create_publisher(MarkerArray, 'obstacles', OBSTACLES_QOS)
    drawn = []
    client.create_subscription(MarkerArray, 'model_obstacle_markers', drawn.append,
                               OBSTACLE_MARKERS_QOS)
    with spinning(rclpy_context, node, client) as executor:
        assert spin_until(executor, lambda: target_pub.get_subscription_count() > 0
                          and obstacles.get_subscription_count() > 0, 10.0)
        target_pub.publish(target_point(BELOW_TABLE))
        assert spin_until(executor, lambda: node.ticks > 30, 10.0)
        held = node.last_result
        bad = MarkerArray(markers=[_ball((0.1, math.nan, 0.1))])
        obstacles.publish(bad)
        assert spin_until(executor, lambda: sum(node.rejected.values()) == 1, 5.0)
        assert [o.name for o in node.solver.obstacles] == ['table', 'post']
        obstacles.publish(MarkerArray(markers=[_ball((0.3, 0.0, 0.3))]))
        assert spin_until(executor, lambda: node.obstacle_updates == 1, 5.0)
        assert [o.name for o in node.solver.obstacles] == ['lab/0']
        assert spin_until(executor, lambda: len(drawn) >= 2, 5.0)   # latched scene set, then this
        obstacles.publish(MarkerArray())
        assert spin_until(executor, lambda: node.obstacle_updates == 2, 5.0)
        ticks = node.ticks
        assert spin_until(executor, lambda: node.ticks > ticks + 30, 10.0)
    assert held.obstacle_rows >= 1 and held.status == 'unreachable'
    assert held.effector_positions[0, 2] > -0.08 + 0.0245
    assert node.rejected == {'obstacles.non_finite': 1}
    assert node.solver.obstacles == () and node.last_result.obstacle_rows == 0
    # the model's obstacles drawn: the scene's (latched at start), then each replacement
    scene_drawn, _, _ = obstacles_from_markers(drawn[0], 'cbha_base')
    ball_drawn, _, _ = obstacles_from_markers(drawn[1], 'cbha_base')
    drawn_shapes = [(o.name, o.shape) for o in scene_drawn]
    assert drawn_shapes == [('obstacles/1', 'box'), ('obstacles/2', 'cylinder')]
    assert [round(o.radius, 6) for o in ball_drawn] == [0.01]
    # without the table the tip reaches the target below it
    assert node.last_result.effector_positions[0, 2] < -0.099
