"""The closed loop's target history and the controller's decisions (pure, no ROS)."""

from cbha_inverse.robot.safety import controller_decision, watchdog_action
from cbha_inverse.robot.targets import TargetHistory
import pytest


def test_the_target_current_at_a_stamp():
    history = TargetHistory(capacity=3)
    assert history.at(5, 'current') == 'current'            # nothing recorded yet
    for stamp, target in ((10, 'a'), (20, 'b'), (30, 'c')):
        history.add(stamp, target)
    assert len(history) == 3
    assert [history.at(s, None) for s in (10, 15, 20, 29, 30)] == ['a', 'a', 'b', 'b', 'c']
    # outside the recorded span (older, or on another clock): the current target
    assert history.at(9, 'current') == 'current' and history.at(31, 'current') == 'current'
    history.add(40, 'd')                                   # the oldest is dropped
    assert len(history) == 3 and history.at(10, 'current') == 'current'
    assert history.at(35, None) == 'c'


@pytest.mark.parametrize('enabled, has_target, stale, closed, action, expected', [
    (False, True, True, True, 'vent', 'disabled'),
    (True, False, True, True, 'vent', 'waiting'),
    (True, True, True, True, 'vent', 'vent'),
    (True, True, True, True, 'hold', 'hold'),
    (True, True, True, False, 'hold', 'run'),       # open loop needs no feedback
    (True, True, False, True, 'hold', 'run'),
])
def test_controller_decision(enabled, has_target, stale, closed, action, expected):
    assert controller_decision(enabled, has_target, stale, closed, action) == expected


@pytest.mark.parametrize('decision, publish_idle, expected', [
    ('hold', False, 'hold'), ('vent', False, 'vent'), ('waiting', True, 'vent'),
    ('waiting', False, None), ('run', True, None), ('disabled', True, None),
])
def test_watchdog_action(decision, publish_idle, expected):
    assert watchdog_action(decision, publish_idle) == expected
