"""
``cbha_sim`` with obstacles over real DDS: the scene's, the ``obstacles`` topic's, contacts.

The sim runs the table scene (``config/scenes/cbha_table.yaml``): it draws the table and the post
on ``obstacle_markers`` (latched); the inner section's over tube at full pressure bends the tip
down onto the table, and ``contacts`` reports the tip's contact (force along the table's normal,
penetration = force / ``contact_stiffness``; drawn as an arrow and a point on
``contacts/markers``) while ``tip/true`` stays on the table. An ``obstacles`` message replaces
the set (the table gone, the tip falls through to where the free plant puts it); malformed
messages are rejected, counted, and change nothing.
"""

import math

from builtin_interfaces.msg import Time
from cbha_inverse.ros.common.conversions import command_message
from cbha_inverse.ros.common.obstacle_markers import (contact_array, CONTACT_COLUMNS,
                                                      obstacle_markers)
from cbha_inverse.ros.common.qos import (COMMAND_QOS, MARKER_QOS, MEASURED_QOS,
                                         OBSTACLE_MARKERS_QOS, OBSTACLES_QOS)
from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode
from geometry_msgs.msg import PointStamped
import numpy as np
import pytest
from rclpy.node import Node
from ros_helpers import make_node, spin_until, spinning
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import Marker, MarkerArray

STIFFNESS = 2.0e4
TABLE_HEIGHT = -0.08
RADIUS = 0.0245


def _marker(kind, scale, position=(0.0, 0.0, 0.0), frame_id='cbha_base', marker_id=0):
    item = Marker()
    item.header.frame_id = frame_id
    item.ns, item.id, item.type, item.action = 'lab', marker_id, kind, Marker.ADD
    item.pose.position.x, item.pose.position.y, item.pose.position.z = position
    item.pose.orientation.w = 1.0
    item.scale.x, item.scale.y, item.scale.z = scale
    return item


def test_sim_presses_on_its_obstacles_and_takes_new_ones(rclpy_context):
    sim = make_node(CbhaSimNode, rclpy_context, namespace='/obst', scene='cbha_table',
                    contact_stiffness=STIFFNESS, noise_std=0.0)
    probe = Node('obstacle_probe', context=rclpy_context)
    drawn, contacts, tips = [], [], []
    probe.create_subscription(MarkerArray, '/obst/obstacle_markers', drawn.append,
                              OBSTACLE_MARKERS_QOS)
    probe.create_subscription(Float64MultiArray, '/obst/contacts', contacts.append, MEASURED_QOS)
    probe.create_subscription(PointStamped, '/obst/tip/true', tips.append, MEASURED_QOS)
    arrows = []
    probe.create_subscription(MarkerArray, '/obst/contacts/markers', arrows.append, MARKER_QOS)
    command = probe.create_publisher(Float64MultiArray, '/obst/pressure_command', COMMAND_QOS)
    obstacles = probe.create_publisher(MarkerArray, '/obst/obstacles', OBSTACLES_QOS)
    names = sim.valve_names
    pressures = [150000.0 if name == 'inner_over' else 0.0 for name in names]

    def touching():
        return contacts and len(contacts[-1].data) == 11 and sim.arm.valves.pressures.max() > (
            0.999 * 150000.0)

    with spinning(rclpy_context, sim, probe) as executor:
        # the scene's obstacles, drawn (latched): a DELETEALL, the table's tile, the post
        assert spin_until(executor, lambda: drawn, 10.0)
        kinds = [m.type for m in drawn[-1].markers[1:]]
        assert drawn[-1].markers[0].action == Marker.DELETEALL
        assert kinds == [Marker.CUBE, Marker.CYLINDER]
        assert spin_until(executor, lambda: command.get_subscription_count() > 0, 10.0)
        command.publish(command_message(pressures, names))
        assert spin_until(executor, touching, 10.0)
        contacts.clear()
        assert spin_until(executor, lambda: len(contacts) >= 3, 10.0)
        layout = contacts[-1].layout.dim
        assert layout[1].label == ','.join(CONTACT_COLUMNS) and layout[0].size == 1
        row = dict(zip(CONTACT_COLUMNS, contacts[-1].data))
        assert row['frame'] == 16
        force = np.array([row['force_x'], row['force_y'], row['force_z']])
        assert force[2] > 0.5 and np.allclose(force[:2], 0.0, atol=1e-12)
        assert abs(row['penetration'] - force[2] / STIFFNESS) < 1e-15
        assert row['point_z'] == TABLE_HEIGHT
        tip = tips[-1].point
        # (the tip of a neighbouring tick: the valves still settle by micrometres)
        assert abs(tip.z - (TABLE_HEIGHT + RADIUS - row['penetration'])) < 1e-6
        # drawn: the force's arrow from the contact point, and the point; the plant's clearance
        # is minus the penetration
        assert spin_until(executor, lambda: len(arrows) >= 3, 10.0)
        drawn_contacts = arrows[-1].markers
        assert drawn_contacts[0].action == Marker.DELETEALL
        assert [m.type for m in drawn_contacts[1:]] == [Marker.ARROW, Marker.SPHERE_LIST]
        arrow, points = drawn_contacts[1:]
        assert (arrow.ns, arrow.id, points.ns) == ('table', 16, 'contact_points')
        assert arrow.points[0].z == points.points[0].z == TABLE_HEIGHT
        assert arrow.points[1].z > TABLE_HEIGHT
        assert sim.arm.plant.clearance == -sim.arm.plant.contacts.penetrations.max()
        assert sim.lowest_clearance <= sim.arm.plant.clearance < 0.0
        # bad obstacle messages: rejected, counted; the table stays
        bad = [MarkerArray(markers=[_marker(Marker.ARROW, (0.1, 0.1, 0.1))]),
               MarkerArray(markers=[_marker(Marker.SPHERE, (0.1, math.nan, 0.1))]),
               MarkerArray(markers=[_marker(Marker.SPHERE, (0.1, 0.1, 0.1), frame_id='map')]),
               MarkerArray(markers=[_marker(Marker.SPHERE, (0.1, 0.1, 0.1)),
                                    _marker(Marker.CUBE, (0.1, 0.1, 0.1))])]
        assert spin_until(executor, lambda: obstacles.get_subscription_count() > 0, 10.0)
        keys = ('obstacles.unknown_shape', 'obstacles.non_finite', 'obstacles.wrong_frame',
                'obstacles.duplicate')
        for message, key in zip(bad, keys):    # one at a time: the topic keeps the newest only
            obstacles.publish(message)
            assert spin_until(executor, lambda key=key: sim.rejected.get(key) == 1, 10.0)
        assert sim.rejected.total == len(keys)
        assert [o.name for o in sim.arm.plant.obstacles] == ['table', 'post']
        # a new set replaces the table: the tip falls to where the free plant puts it
        drawn.clear()
        ball = _marker(Marker.SPHERE, (0.04, 0.04, 0.04), position=(0.0, 0.3, 0.0))
        obstacles.publish(MarkerArray(markers=[ball]))
        assert spin_until(executor, lambda: drawn and len(contacts[-1].data) == 0, 10.0)
        assert [o.name for o in sim.arm.plant.obstacles] == ['lab/0']
        assert [m.type for m in drawn[-1].markers[1:]] == [Marker.SPHERE]
        tips.clear()
        assert spin_until(executor, lambda: tips, 10.0)
        assert tips[-1].point.z < TABLE_HEIGHT + RADIUS - 0.01
    assert sim.obstacle_updates == 1


def test_markers_round_trip_and_contact_rows():
    """What obstacle_markers draws of a sphere, box and cylinder reads back as the same solids."""
    from cbha_inverse.core.contact import Contacts
    from cbha_inverse.core.obstacles import obstacle_from_rpy
    from cbha_inverse.ros.common.obstacle_markers import obstacles_from_markers
    solids = [obstacle_from_rpy('ball', 'sphere', [0.1, 0.2, 0.3], [0.1, 0.2, 0.3], radius=0.02),
              obstacle_from_rpy('crate', 'box', [0.0, -0.1, 0.0], [0.5, -0.2, 1.0],
                                size=[0.1, 0.2, 0.3]),
              obstacle_from_rpy('post', 'cylinder', [0.2, 0.0, 0.0], [0.0, 0.4, 0.0],
                                radius=0.015, length=0.3)]
    drawn = obstacle_markers(solids, Time(), 'cbha_base')
    back, key, detail = obstacles_from_markers(drawn, 'cbha_base')
    assert key is None, detail
    points = np.random.default_rng(0).uniform(-0.3, 0.3, size=(50, 3))
    for solid, read in zip(solids, back):
        assert read.shape == solid.shape
        np.testing.assert_allclose(read.signed_distance(points).distance,
                                   solid.signed_distance(points).distance, atol=1e-12)
    contacts = Contacts(np.array([3, 7]), ('a', 'b'), np.ones((2, 3)), np.eye(3)[:2],
                        np.array([1e-4, 2e-4]), np.arange(6.0).reshape(2, 3))
    rows = np.reshape(contact_array(contacts).data, (2, 11))
    np.testing.assert_array_equal(rows[:, 0], [3, 7])
    np.testing.assert_array_equal(rows[:, 7], [1e-4, 2e-4])
    np.testing.assert_array_equal(rows[:, 8:], np.arange(6.0).reshape(2, 3))


def test_planes_and_capsules_are_drawn_with_the_shapes_markers_have():
    """A plane: a thin tile whose top lies on the plane; a capsule: a cylinder and two balls."""
    from cbha_inverse.core.obstacles import obstacle_from_rpy
    plane = obstacle_from_rpy('wall', 'plane', [0.3, 0.0, 0.0], [0.0, -np.pi / 2, 0.0])
    capsule = obstacle_from_rpy('rail', 'capsule', [0.0, 0.1, 0.0], [0.0, 0.0, 0.0],
                                radius=0.01, length=0.2)
    markers = obstacle_markers([plane, capsule], Time(), 'cbha_base').markers
    assert markers[0].action == Marker.DELETEALL
    tile, cylinder, low, high = markers[1:]
    assert (tile.type, cylinder.type, low.type, high.type) == (
        Marker.CUBE, Marker.CYLINDER, Marker.SPHERE, Marker.SPHERE)
    # the wall's free side is -x: the tile's top face (+z of the tile) lies on x = 0.3
    assert tile.scale.z == 0.001 and tile.pose.position.x == pytest.approx(0.3005)
    assert [low.pose.position.z, high.pose.position.z] == pytest.approx([-0.1, 0.1])
    assert (cylinder.scale.x, cylinder.scale.z) == pytest.approx((0.02, 0.2))
