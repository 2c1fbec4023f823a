"""
``cbha_demo`` records every run into a bag; ``cbha_bag eval`` on it gives the RMS the demo printed.

One short demo (one small circle, open loop, then a short excitation: ~20 s), run as ``make demo``
runs it, is shared by the tests: the lap's bag is evaluated by the ``cbha_bag eval`` command with
the window the demo stored, and read by the independent ``mcap`` + ``mcap-ros2-support`` reader
(every recorded topic, the plant's valve pressures among them); the excitation's bag is read too.
"""

import json
import re
import subprocess
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
from ros_helpers import aborted_logs, child_env, REPO_ROOT


@pytest.fixture(scope='module')
def demo(tmp_path_factory):
    """
    Run ``cbha_demo``: one small open-loop circle, then the ``outer_bends`` excitation.

    Returns
    -------
    output : pathlib.Path
        The demo's ``--output`` folder.
    stdout : str
        What it printed.

    """
    output = tmp_path_factory.mktemp('demo_bags') / 'demo'
    process = subprocess.run(
        [sys.executable, '-m', 'cbha_inverse.experiments.demo', '--output', str(output),
         '--shapes', 'circle', '--modes', 'open', '--feedback', 'direct', '--radius', '0.005',
         '--start-hold', '0.5', '--excite', 'outer_bends', '--excite-hold-time', '0.3',
         '--excite-ramp-time', '0.2'],
        cwd=REPO_ROOT, env=child_env(), capture_output=True, text=True, timeout=240)
    assert process.returncode == 0, process.stdout + process.stderr + aborted_logs(output)
    return output, process.stdout


def test_demo_bag_eval_gives_the_printed_rms(demo, tmp_path):
    """Same RMS and max to 1e-6 mm; the bag has every recorded topic and decodes elsewhere."""
    output, stdout = demo
    printed = float(re.search(r'circle open  : RMS +([0-9.]+) mm', stdout).group(1))
    (run,) = json.loads((output / 'summary.json').read_text())['runs']
    assert run['rms_mm'] == pytest.approx(printed, abs=5e-4)  # printed with 3 decimals
    start, end = run['eval_window_s']
    evaluated = subprocess.run(
        [sys.executable, '-m', 'cbha_inverse.ros.bag.cli', 'eval', run['bag'], '--start',
         repr(start), '--end', repr(end), '--plot', str(tmp_path / 'eval.png')],
        cwd=REPO_ROOT, env=child_env(), capture_output=True, text=True, timeout=120)
    assert evaluated.returncode == 0, evaluated.stderr
    match = re.search(r'RMS ([0-9.]+) mm, max ([0-9.]+) mm over (\d+) samples', evaluated.stdout)
    assert float(match.group(1)) == pytest.approx(run['rms_mm'], abs=1e-6)
    assert float(match.group(2)) == pytest.approx(run['max_mm'], abs=1e-6)
    assert int(match.group(3)) == run['samples']
    assert (tmp_path / 'eval.png').stat().st_size > 10_000
    topics = {}
    for file in sorted((output / 'circle_open' / 'bag').glob('*.mcap')):
        with open(file, 'rb') as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            for _, channel, _, message in reader.iter_decoded_messages():
                topics.setdefault(channel.topic, []).append(message)
    assert set(topics) == {'/cbha/target', '/cbha/tip/true', '/cbha/tip/measured',
                           '/cbha/pressure_command', '/cbha/pressure_measured',
                           '/cbha/string_pots', '/diagnostics'}
    assert all(len(message.data) == 6 for message in topics['/cbha/pressure_command'])
    # the plant's valve pressures (noise-free by default): within the commands' range
    commanded = np.array([message.data for message in topics['/cbha/pressure_command']])
    measured = np.array([message.data for message in topics['/cbha/pressure_measured']])
    assert measured.shape[1] == 6 and len(measured) > 100
    assert np.all(measured >= 0.0) and np.all(measured <= commanded.max(axis=0) + 1e-6)
    assert topics['/cbha/target'][0].header.frame_id == 'cbha_base'


def test_demo_excite_records_the_program_on_the_plant(demo):
    """
    ``cbha_demo --excite``: after the lap, cbha_sim + cbha_excite alone, recorded (~6 s).

    The excitation bag holds exactly the four identification topics; the commands start and end
    at mid range and reach every hold of the program; the plant's valve pressures settle on every
    hold (10 ms valves, 0.3 s holds) and its tip moves between the three outer bends.
    """
    from cbha_inverse.identify.excitation import make_program
    from cbha_inverse.ros.nodes.cbha_excite import ExciteParams
    from cbha_inverse.scene import load_scene
    output, stdout = demo
    summary = json.loads((output / 'summary.json').read_text())
    assert [run['shape'] for run in summary['runs']] == ['circle']
    excitation = summary['excitation']
    bag = output / 'excite_outer_bends' / 'bag'
    assert excitation['bag'] == str(bag) and excitation['holds'] == 3
    assert excitation['exit_codes'] == {'cbha_sim': 0, 'cbha_excite': 0, 'cbha_bag_record': 0}
    assert 'excite outer_bends: 3 holds, 1.7 s' in stdout
    topics, log_times = {}, {}
    for file in sorted(bag.glob('*.mcap')):
        with open(file, 'rb') as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            for _, channel, record, message in reader.iter_decoded_messages():
                topics.setdefault(channel.topic, []).append(message)
                log_times.setdefault(channel.topic, []).append(record.log_time)
    assert set(topics) == {'/cbha/pressure_command', '/cbha/pressure_measured',
                           '/cbha/tip/measured', '/cbha/tip/true'}
    assert {t: len(m) for t, m in topics.items()} == excitation['messages']
    program = make_program(load_scene('cbha'), 'outer_bends', hold_time=0.3, ramp_time=0.2)
    commands = np.array([m.data for m in topics['/cbha/pressure_command']])
    measured = np.array([m.data for m in topics['/cbha/pressure_measured']])
    np.testing.assert_array_equal(commands[0], program.start)
    np.testing.assert_array_equal(commands[-1], program.end)
    assert np.all(commands >= 0.0) and np.all(commands <= ExciteParams.max_pressure)
    # each tip sample with the valve pressures last received before it
    tip = np.array([[m.point.x, m.point.y, m.point.z] for m in topics['/cbha/tip/true']])
    latest = np.searchsorted(log_times['/cbha/pressure_measured'], log_times['/cbha/tip/true'],
                             side='right') - 1
    tips = []
    for _, _, pressures in program.holds:
        assert np.any(np.all(commands == pressures, axis=1))
        settled = np.all(np.abs(measured - pressures) < 1.0, axis=1)
        assert settled.sum() >= 5, pressures
        tips.append(tip[(latest >= 0) & settled[np.maximum(latest, 0)]].mean(axis=0))
    # the three bends point the tip three different ways: pairwise several centimetres apart
    gaps = [np.linalg.norm(tips[i] - tips[j]) for i in range(3) for j in range(i)]
    assert min(gaps) > 0.03, gaps
