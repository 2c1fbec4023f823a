"""``feedback:=proprio``: the compositions close the loop on the string-pot estimate."""

from cbha_inverse.ros.launch.compositions import COMPOSITIONS, resolve
import pytest


@pytest.mark.parametrize('name', ['sim', 'robot'])
def test_proprio_starts_the_estimator_and_feeds_its_tip_to_the_solver(name):
    nodes = {p.executable: p for p in resolve(COMPOSITIONS[name], {'feedback': 'proprio'})}
    assert 'shape_estimator' in nodes and 'stereo_tracker' not in nodes
    assert nodes['inverse_solver'].parameters['feedback_topic'] == 'tip/estimated'
    assert nodes['shape_estimator'].parameters == {'scene': 'cbha.yaml'}
    if name == 'sim':
        assert nodes['cbha_sim'].parameters['tip_output'] == 'none'


@pytest.mark.parametrize('name, feedback', [('sim', 'sim'), ('sim', 'stereo'),
                                            ('robot', 'stereo'), ('robot', 'none')])
def test_other_feedback_keeps_the_measured_tip(name, feedback):
    nodes = {p.executable: p for p in resolve(COMPOSITIONS[name], {'feedback': feedback})}
    assert 'shape_estimator' not in nodes
    assert 'feedback_topic' not in nodes['inverse_solver'].parameters
