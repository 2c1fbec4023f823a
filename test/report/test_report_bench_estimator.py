"""Smoke test of cbha_bench_estimator on a short lap."""

import json

from cbha_inverse.bag.storage import BagWriter
from cbha_inverse.report import bench_estimator
import numpy as np
from rosbags.typesys import get_typestore, Stores


def test_bench_estimator_runs(capsys, tmp_path):
    """The benchmark prints its two lines; the estimate beats the open-loop model."""
    out = tmp_path / 'row.json'
    assert bench_estimator.main(['--poses', '40', '--json', str(out)]) == 0
    text = capsys.readouterr().out
    assert 'estimator update median' in text and 'open-loop model RMS' in text
    row = json.loads(out.read_text())
    assert row['updates'] == 40 and row['degraded'] == 0
    assert row['rms'] < 0.5 * row['open_loop_rms']


def test_the_lap_sweeps_both_sections():
    lap = bench_estimator.pressure_lap(12)
    assert lap.shape == (12, 6)
    assert lap.min() >= 0.0 and lap.max() <= 1.5e5
    assert (lap[:, :3].argmax(axis=1) != lap[:, 3:].argmax(axis=1)).any()


def _array_bytes(typestore, values):
    message = typestore.types['std_msgs/msg/Float64MultiArray'](
        layout=typestore.types['std_msgs/msg/MultiArrayLayout'](dim=[], data_offset=0),
        data=np.asarray(values, dtype=float))
    return bytes(typestore.serialize_cdr(message, 'std_msgs/msg/Float64MultiArray'))


def _point_bytes(typestore, k):
    types = typestore.types
    message = types['geometry_msgs/msg/PointStamped'](
        header=types['std_msgs/msg/Header'](
            stamp=types['builtin_interfaces/msg/Time'](sec=k, nanosec=0), frame_id='cbha_base'),
        point=types['geometry_msgs/msg/Point'](x=0.2, y=0.0, z=0.0))
    return bytes(typestore.serialize_cdr(message, 'geometry_msgs/msg/PointStamped'))


def test_a_demo_bag_replays_its_measured_pressures_in_its_lap_window(tmp_path):
    """bag_lap: the pressures in the order received, measured from 1.5 s after the first target."""
    typestore = get_typestore(Stores.ROS2_JAZZY)
    lap = bench_estimator.pressure_lap(30)
    writer = BagWriter(tmp_path / 'bag')
    writer.add_topic('/cbha/pressure_measured', 'std_msgs/msg/Float64MultiArray', [])
    writer.add_topic('/cbha/target', 'geometry_msgs/msg/PointStamped', [])
    # pressures every 100 ms from t = 0, targets from 0.5 s to 2.5 s: window 2.0-2.5 s
    for k, pressures in enumerate(lap):
        writer.write('/cbha/pressure_measured', 10 ** 9 + k * 10 ** 8,
                     _array_bytes(typestore, pressures))
    for k in range(5):
        writer.write('/cbha/target', 10 ** 9 + 5 * 10 ** 8 + k * 5 * 10 ** 8,
                     _point_bytes(typestore, k))
    writer.close()
    pressures, measured = bench_estimator.bag_lap(tmp_path / 'bag')
    np.testing.assert_array_equal(pressures, lap)
    assert np.flatnonzero(measured).tolist() == [20, 21, 22, 23, 24, 25]
    row = bench_estimator.bench(laps=1, lap=pressures, measured=measured)
    assert row['updates'] == 6 and len(row['bias']) == 3
    assert row['rms'] < 0.5 * row['open_loop_rms']
