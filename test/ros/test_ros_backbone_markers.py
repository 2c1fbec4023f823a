"""
The RViz markers of the backbone (:func:`cbha_inverse.ros.common.conversions.backbone_markers`).

Line strip and spheres through the frame origins, the target sphere, their ids, header,
namespace, colours and sizes, and the array without a target.
"""

from builtin_interfaces.msg import Time
from cbha_inverse.ros.common.conversions import backbone_markers
import numpy as np
from visualization_msgs.msg import Marker


def test_backbone_markers_draw_the_frames_and_the_target():
    positions = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.2, 0.01, -0.02]])
    stamp = Time(sec=12, nanosec=34)
    markers = backbone_markers(positions, (0.3, 0.1, -0.1), stamp, 'cbha_base').markers
    assert [m.type for m in markers] == [Marker.LINE_STRIP, Marker.SPHERE_LIST, Marker.SPHERE]
    assert [m.id for m in markers] == [0, 1, 2]
    for marker in markers:
        assert marker.header.frame_id == 'cbha_base' and marker.header.stamp == stamp
        assert marker.ns == 'backbone' and marker.action == Marker.ADD
        assert marker.pose.orientation.w == 1.0 and marker.color.a == 1.0
        assert marker.scale.x == marker.scale.y == marker.scale.z > 0.0
    for marker in markers[:2]:
        np.testing.assert_array_equal([[p.x, p.y, p.z] for p in marker.points], positions)
    goal = markers[2].pose.position
    assert (goal.x, goal.y, goal.z) == (0.3, 0.1, -0.1)
    assert [(m.color.r, m.color.g, m.color.b) for m in markers] == [
        (0.2, 0.5, 1.0), (0.9, 0.9, 0.9), (1.0, 0.3, 0.1)]
    assert [m.scale.x for m in markers] == [0.004, 0.008, 0.01]
    no_target = backbone_markers(positions, None, stamp, 'map', namespace='model').markers
    assert len(no_target) == 2 and {m.ns for m in no_target} == {'model'}
