"""Left/right image pairing by stamp (the stereo_tracker's queues), without ROS."""

from cbha_inverse.vision.pairing import DropMonitor, StereoPairer
import pytest


def test_images_pair_by_the_closest_stamp_within_max_dt():
    pairer = StereoPairer(max_dt=0.002, queue_size=3)
    assert pairer.add('left', 1.000, 'L1') == (None, ())
    assert pairer.add('left', 1.010, 'L2') == (None, ())
    # a right image 1.5 ms after L2 pairs with it; L1, older than the pair, is dropped
    assert pairer.add('right', 1.0115, 'R2') == (('L2', 'R2'), ('superseded',))
    assert not pairer.queues['left'] and not pairer.queues['right']
    # too far apart (3 ms): both wait
    assert pairer.add('right', 1.020, 'R3') == (None, ())
    assert pairer.add('left', 1.023, 'L3') == (None, ())
    # the left partner of a right image is returned first: (left, right)
    assert pairer.add('right', 1.0235, 'R4') == (('L3', 'R4'), ('superseded',))


def test_a_full_queue_drops_its_oldest_image():
    pairer = StereoPairer(max_dt=0.0, queue_size=2)
    assert pairer.add('left', 1.0, 'a') == (None, ())
    assert pairer.add('left', 2.0, 'b') == (None, ())
    assert pairer.add('left', 3.0, 'c') == (None, ('no_partner',))
    assert [item for _, item in pairer.queues['left']] == ['b', 'c']
    # exact stamps pair with max_dt 0
    assert pairer.add('right', 3.0, 'r') == (('c', 'r'), ('superseded',))


def test_drop_monitor_tells_occasional_drops_from_falling_behind():
    monitor = DropMonitor(window=20, share=0.25)
    # one image in ten dropped (normal running of two free streams): never behind
    assert not any(monitor.add(1 if i % 10 == 0 else 0) for i in range(200))
    # one in three: behind, once the window holds enough of them
    behind = [monitor.add(1 if i % 3 == 0 else 0) for i in range(40)]
    assert not behind[0] and behind[-1]
    # back to normal: no longer behind after a window
    assert not [monitor.add(0) for _ in range(20)][-1]
    with pytest.raises(ValueError):
        DropMonitor(window=0)
