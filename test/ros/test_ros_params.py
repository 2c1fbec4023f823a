"""Every node parameter is declared with a type, a description and (for numbers) a range."""

from dataclasses import fields, is_dataclass
import sys

from cbha_inverse.ros.common.params import ParameterError
from cbha_inverse.ros.nodes.cbha_excite import ExciteNode
from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from cbha_inverse.ros.nodes.shape_estimator import ShapeEstimatorNode
from cbha_inverse.ros.nodes.stereo_tracker import StereoTrackerNode
from cbha_inverse.ros.nodes.trajectory import TrajectoryNode
from cbha_inverse.scene import load_scene
import pytest
from rcl_interfaces.msg import ParameterType
from rclpy.parameter import Parameter

SCENE = 'tendon_6f_8c'


def _params_class(node_class):
    module = sys.modules[node_class.__module__]
    [found] = [v for k, v in vars(module).items() if k.endswith('Params') and is_dataclass(v)
               and v.__module__ == module.__name__]
    return found


def _overrides(node_class):
    if node_class in (TrajectoryNode, StereoTrackerNode, ShapeEstimatorNode):
        return []
    names = list(load_scene(SCENE).actuator_names)
    program = [Parameter('program', value='extension')] if node_class is ExciteNode else []
    return [Parameter('scene', value=SCENE), Parameter('valve_names', value=names), *program]


@pytest.mark.parametrize('node_class', [TrajectoryNode, InverseSolverNode, CbhaSimNode,
                                        StereoTrackerNode, ShapeEstimatorNode, ExciteNode])
def test_every_parameter_is_described_typed_and_ranged(rclpy_context, node_class):
    node = node_class(context=rclpy_context, parameter_overrides=_overrides(node_class))
    try:
        names = [name for name in node.list_parameters([], 0).names
                 if name not in ('use_sim_time', 'start_type_description_service')]
        descriptors = node.describe_parameters(names)
    finally:
        node.destroy_node()
    assert len(descriptors) >= 10
    live = {spec.metadata.get('ros_name') or spec.name: spec.metadata['live']
            for spec in fields(_params_class(node_class))}
    for descriptor in descriptors:
        assert descriptor.description, f'{descriptor.name} has no description'
        # tuning parameters are live, the structural ones read-only (and say so)
        assert descriptor.read_only == (not live[descriptor.name]), descriptor.name
        assert descriptor.read_only == descriptor.description.endswith(
            '(read-only: restart the node to change it)'), descriptor.name
        assert descriptor.type != ParameterType.PARAMETER_NOT_SET
        if descriptor.type == ParameterType.PARAMETER_DOUBLE:
            assert descriptor.floating_point_range, f'{descriptor.name} has no range'
        if descriptor.type == ParameterType.PARAMETER_INTEGER:
            assert descriptor.integer_range, f'{descriptor.name} has no range'


@pytest.mark.parametrize('override, match', [
    (Parameter('valve_names', value=['a', 'b']), 'permutation'),
    (Parameter('mode', value='half'), 'mode'),
    (Parameter('workspace_min', value=[1.0, 1.0, 1.0]), 'below'),
    (Parameter('scene', value='no_such_scene'), 'no scene'),
    (Parameter('rate_hz', value=0.0), 'out of range'),
])
def test_inverse_solver_rejects_bad_parameters(rclpy_context, override, match):
    overrides = [p for p in _overrides(InverseSolverNode) if p.name != override.name]
    with pytest.raises(ParameterError, match=match):
        InverseSolverNode(context=rclpy_context, parameter_overrides=overrides + [override])


@pytest.mark.parametrize('override, match', [
    (Parameter('gravity', value=[0.0, 9.81]), 'gravity'),
    (Parameter('stiffness_scale', value=-1.0), 'out of range'),
    (Parameter('valve_names', value=['x']), 'permutation'),
    (Parameter('section_stiffness_scale', value=[0.9]), 'section_stiffness_scale'),
    (Parameter('cavity_gain_scale', value=[1.0, -1.0]), 'cavity_gain_scale'),
])
def test_cbha_sim_rejects_bad_parameters(rclpy_context, override, match):
    overrides = [p for p in _overrides(CbhaSimNode) if p.name != override.name]
    with pytest.raises(ParameterError, match=match):
        CbhaSimNode(context=rclpy_context, parameter_overrides=overrides + [override])
