from cbha_inverse.ros.common.rejections import Rejections, ThrottledLog
import rclpy.logging


class _Clock:

    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


def _rejections(throttle):
    clock = _Clock()
    limit = [throttle]
    log = ThrottledLog(rclpy.logging.get_logger('test_rejections'), lambda: limit[0], clock)
    return Rejections(log), clock, limit


def test_counts_by_key_and_reports_the_diagnostics_key_values():
    rejections, _, _ = _rejections(0.0)
    rejections.count('target.non_finite', 'rejected target: non-finite point')
    rejections.count('dropped_unpaired', None, number=3)
    rejections.count('target.non_finite', 'rejected target: non-finite point')
    assert rejections == {'target.non_finite': 2, 'dropped_unpaired': 3}
    assert rejections.total == 5
    assert list(rejections.key_values().items()) == [
        ('rejected_total', 5), ('rejected.dropped_unpaired', 3), ('rejected.target.non_finite', 2)]


def test_the_log_is_throttled_per_key_and_the_throttle_can_change():
    rejections, clock, limit = _rejections(1.0)
    assert rejections.count('a', 'a: bad')
    assert not rejections.count('a', 'a: bad')
    assert rejections.count('b', 'b: bad', error=True)   # another key is not hidden
    assert rejections.log.warning('degraded', 'degraded estimate')
    clock.now = 0.99
    assert not rejections.count('a', 'a: bad')
    assert not rejections.log.error('degraded', 'degraded estimate')
    clock.now = 1.0
    assert rejections.count('a', 'a: bad')
    limit[0] = 5.0                                       # a live log_throttle applies at once
    clock.now = 5.5
    assert not rejections.count('a', 'a: bad')
    clock.now = 6.0
    assert rejections.count('a', 'a: bad')
    assert rejections == {'a': 6, 'b': 1}
