"""``inverse_solver`` on a scene with a zero-range actuator: one line naming it."""

from pathlib import Path

from cbha_inverse.ros.common.params import ParameterError
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
import pytest
from rclpy.parameter import Parameter
import yaml

SCENES = Path(__file__).resolve().parents[2] / 'config' / 'scenes'


def test_inverse_solver_refuses_a_zero_range_actuator(rclpy_context, tmp_path):
    """max_tension: 0 is a ParameterError naming file and key, not a division by zero."""
    spec = yaml.safe_load((SCENES / 'tendon_6f_8c.yaml').read_text(encoding='utf-8'))
    spec['cables'][1]['max_tension'] = 0.0
    scene = tmp_path / 'zero_range.yaml'
    scene.write_text(yaml.safe_dump(spec), encoding='utf-8')
    names = [cable['name'] for cable in spec['cables']]
    with pytest.raises(ParameterError, match=r'zero_range\.yaml: cables\[1\]\.max_tension') as err:
        InverseSolverNode(context=rclpy_context, parameter_overrides=[
            Parameter('scene', value=str(scene)), Parameter('valve_names', value=names),
            Parameter('max_pressure', value=10.0)])
    assert '\n' not in str(err.value)
