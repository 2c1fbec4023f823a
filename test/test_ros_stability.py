"""The ``inverse_solver`` node starts on a scene with a zero-range actuator (issue 11)."""

from pathlib import Path

from cbha_inverse.ros.inverse_solver_node import InverseSolverNode
from rclpy.parameter import Parameter
import yaml

SCENES = Path(__file__).resolve().parents[1] / 'config' / 'scenes'


def test_inverse_solver_starts_with_a_zero_range_actuator(rclpy_context, tmp_path):
    """max_tension: 0 used to raise ZeroDivisionError in the warm-up tick (exit 1)."""
    spec = yaml.safe_load((SCENES / 'tendon_6f_8c.yaml').read_text(encoding='utf-8'))
    spec['cables'][1]['max_tension'] = 0.0
    scene = tmp_path / 'zero_range.yaml'
    scene.write_text(yaml.safe_dump(spec), encoding='utf-8')
    names = [cable['name'] for cable in spec['cables']]
    node = InverseSolverNode(context=rclpy_context, parameter_overrides=[
        Parameter('scene', value=str(scene)), Parameter('valve_names', value=names),
        Parameter('max_pressure', value=10.0)])
    try:
        assert any('tip_90' in text for text in node.solver.warnings)
        assert node.upper[names.index('tip_90')] == 0.0
    finally:
        node.destroy_node()
