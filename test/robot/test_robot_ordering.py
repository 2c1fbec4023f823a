"""The measurement stream's order: duplicated and older samples dropped (pure, no ROS)."""

from cbha_inverse.robot.ordering import StampOrder
import numpy as np


def test_duplicated_and_older_samples_are_dropped_and_counted():
    order = StampOrder()
    verdicts = [order.admit(s) for s in (10, 20, 20, 15, 30, 0, 30, 25, 40)]
    assert verdicts == ['restarted', 'admitted', 'duplicate', 'older', 'admitted', 'unstamped',
                        'duplicate', 'older', 'admitted']
    assert order.dropped == {'duplicate': 2, 'older': 2} and order.last == 40


def test_a_stale_gap_restarts_the_order():
    order = StampOrder()
    assert order.admit(100) == 'restarted'
    assert order.admit(50) == 'older'
    # the publisher restarted (its clock from zero): after the stream went stale it is followed
    assert order.admit(50, stale=True) == 'restarted'
    assert order.admit(60) == 'admitted' and order.last == 60


def test_a_shuffled_duplicated_stream_admits_exactly_its_running_records():
    """Against an independent reference: the admitted stamps are the strict running maxima."""
    rng = np.random.default_rng(3)
    stamps = np.arange(1, 201) * 10_000_000
    stream = np.repeat(stamps, rng.choice([1, 2], stamps.size, p=[0.7, 0.3]))  # duplicated
    # reorder: each sample late by up to 3 places
    stream = stream[np.argsort(np.arange(stream.size) + rng.uniform(0.0, 3.0, stream.size))]
    order = StampOrder()
    admitted = [s for s in stream if order.admit(s) in ('admitted', 'restarted')]
    records = [s for i, s in enumerate(stream) if i == 0 or s > stream[:i].max()]
    assert admitted == records
    assert np.all(np.diff(admitted) > 0)
    assert sum(order.dropped.values()) == stream.size - len(admitted)
    assert order.dropped['duplicate'] > 0 and order.dropped['older'] > 0
