"""The closed loop's target history and the controller's decisions (pure, no ROS)."""

from cbha_inverse.robot.safety import controller_decision, SilenceWarning, watchdog_action
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


@pytest.mark.parametrize('closed, action, expected', [
    (True, 'hold', 'waiting'), (True, 'vent', 'waiting'), (False, 'hold', 'run')])
def test_a_closed_loop_without_any_measurement_waits(closed, action, expected):
    # stale because none ever came: nothing to hold yet
    assert controller_decision(True, True, True, closed, action, has_feedback=False) == expected
    assert controller_decision(False, True, True, closed, action, has_feedback=False) == (
        'disabled')


def test_silence_warning_once_then_every_period():
    warning = SilenceWarning(timeout=0.5, period=10.0, start=100.0)
    ticks = [100.0 + 0.1 * k for k in range(301)]          # 30 s without any input
    warned = [t for t in ticks if warning.due(t, None)]
    assert [round(t - 100.0, 1) for t in warned] == [0.6, 10.6, 20.6]
    # inputs end the silence; the next silence is warned again after the timeout
    assert not warning.due(131.0, 130.9)
    assert not warning.due(131.3, 130.9)
    assert warning.due(131.5, 130.9)
    assert not warning.due(131.6, 130.9)
    with pytest.raises(ValueError, match='period'):
        SilenceWarning(0.5, 0.0, 0.0)


@pytest.mark.parametrize('decision, publish_idle, expected', [
    ('hold', False, 'hold'), ('vent', False, 'vent'), ('waiting', True, 'vent'),
    ('waiting', False, None), ('run', True, None), ('disabled', True, None),
])
def test_watchdog_action(decision, publish_idle, expected):
    assert watchdog_action(decision, publish_idle) == expected
