"""
``cbha_bag eval`` on a bag written here: the start-up transient, the plot's path, the tip topic.

The bag holds a target circle and a tip that starts 20 mm off, converges (time constant 0.3 s)
and then follows with a 1 mm offset: with the transient left out the scored RMS is near the
offset, with it far larger.
"""

from cbha_inverse.bag.storage import BagWriter
from cbha_inverse.metrics import transient_end
from cbha_inverse.ros.bag.cli import main as cbha_bag
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
POINT = 'geometry_msgs/msg/PointStamped'
RATE, DURATION, OFFSET = 50.0, 10.0, 1e-3


def _point(stamp, point):
    types = TYPESTORE.types
    message = types[POINT](
        header=types['std_msgs/msg/Header'](
            stamp=types['builtin_interfaces/msg/Time'](sec=int(stamp),
                                                       nanosec=int(round(stamp % 1 * 1e9))),
            frame_id='cbha_base'),
        point=types['geometry_msgs/msg/Point'](x=float(point[0]), y=float(point[1]),
                                               z=float(point[2])))
    return bytes(TYPESTORE.serialize_cdr(message, POINT))


@pytest.fixture
def bag(tmp_path):
    path = tmp_path / 'run'
    writer = BagWriter(path)
    writer.add_topic('/cbha/target', POINT)
    writer.add_topic('/cbha/tip/measured', POINT)
    for k in range(int(DURATION * RATE)):
        t = 100.0 + k / RATE
        target = np.array([0.2, 0.01 * np.cos(t), 0.01 * np.sin(t)])
        # 20 mm off at the start, decaying with 0.3 s, then a 1 mm offset along z
        tip = target + [0.0, 0.02 * np.exp(-(t - 100.0) / 0.3), OFFSET]
        writer.write('/cbha/target', int(t * 1e9), _point(t, target))
        writer.write('/cbha/tip/measured', int(t * 1e9) + 1, _point(t, tip))
    writer.close()
    return path


def test_eval_leaves_the_start_up_transient_out_by_default(bag, capsys):
    assert cbha_bag(['eval', str(bag)]) == 0
    out = capsys.readouterr().out
    assert out.startswith('tracking (/cbha/tip/measured): RMS '), out
    # the transient ends when the error falls to 3x the settled 1 mm:
    # sqrt(1 + (20 exp(-t / 0.3))^2) = 3 mm at t = 0.3 ln(20 / sqrt(8)) = 0.587 s
    skipped = float(out.split('scored from ')[1].split(' s')[0])
    assert skipped == pytest.approx(0.3 * np.log(20.0 / np.sqrt(8.0)), abs=0.03), out
    rms = float(out.split('RMS ')[1].split(' mm')[0])
    assert 1.0 < rms < 1.1, out
    assert cbha_bag(['eval', str(bag), '--start', '0']) == 0
    out = capsys.readouterr().out
    rms = float(out.split('RMS ')[1].split(' mm')[0])
    assert rms > 2.0 and 'scored from' not in out, out


def test_eval_plot_into_a_missing_folder_is_one_line(bag, tmp_path, capsys):
    target = tmp_path / 'nodir' / 'x.png'
    assert cbha_bag(['eval', str(bag), '--plot', str(target)]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and err.startswith(
        f'cbha_bag eval: error: {target}: cannot write the plot: '), err
    assert cbha_bag(['eval', str(bag), '--plot', str(tmp_path / 'x.png')]) == 0
    assert (tmp_path / 'x.png').stat().st_size > 10_000


def test_transient_end():
    times = np.arange(100) * 0.1
    settled = np.full(100, 1.0)
    assert transient_end(times, settled) == 0.0
    errors = settled.copy()
    errors[:15] = 10.0            # the start-up transient
    errors[70] = 50.0             # a later excursion stays in the score
    assert transient_end(times, errors) == pytest.approx(1.5)
    errors[30] = 4.0              # above 3x the settled median within the first half
    assert transient_end(times, errors) == pytest.approx(3.1)


def test_eval_reads_units_and_bounds_from_the_scene(bag, tmp_path, capsys):
    from cbha_inverse.bag.storage import open_bag
    from cbha_inverse.scene import load_scene
    # the tendon trunk's 8 tensions [N]: 0 N (slack) or 10 N (its max_tension) saturate
    scene = load_scene('tendon_6f_8c')
    tensions = np.array([[0.0, 2.0, 5.0, 10.0, 3.0, 3.0, 3.0, 3.0]] * 4)
    path = tmp_path / 'tendons'
    writer = BagWriter(path)
    with open_bag(bag) as source:
        for topic in source.summary.topics:
            writer.add_topic(topic.name, topic.msgtype)
        for topic, stamp, data in source.messages([t.name for t in source.summary.topics]):
            writer.write(topic, stamp, data)
    writer.add_topic('/cbha/pressure_command', 'std_msgs/msg/Float64MultiArray')
    for k, values in enumerate(tensions):
        message = TYPESTORE.types['std_msgs/msg/Float64MultiArray'](
            layout=TYPESTORE.types['std_msgs/msg/MultiArrayLayout'](dim=[], data_offset=0),
            data=values)
        writer.write('/cbha/pressure_command', int((100.0 + k) * 1e9) + 2,
                     bytes(TYPESTORE.serialize_cdr(message, 'std_msgs/msg/Float64MultiArray')))
    writer.close()
    assert list(scene.upper_bounds) == [10.0] * 8
    assert cbha_bag(['eval', str(path), '--scene', 'tendon_6f_8c']) == 0
    out = capsys.readouterr().out
    assert 'per valve [N] min 0.000 2.000 5.000 10.000 3.000' in out, out
    assert 'saturation: 100.0 % of commands, per valve 100.0 0.0 0.0 100.0 0.0' in out, out
    # without the scene (the CBHA's 6 cavities) the 8 values do not fit: one line
    assert cbha_bag(['eval', str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'the commands have 8 values, the scene 6' in err, err


def test_eval_plot_names_the_tip_topic_it_scores(bag, tmp_path):
    import matplotlib
    path = tmp_path / 'run.svg'
    with matplotlib.rc_context({'svg.fonttype': 'none'}):     # the legend as text
        assert cbha_bag(['eval', str(bag), '--plot', str(path)]) == 0
    svg = path.read_text()
    assert '/cbha/tip/measured' in svg and 'target' in svg
    assert 'tip (plant)' not in svg
