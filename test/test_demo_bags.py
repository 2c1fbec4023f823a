"""
``cbha_demo`` records every run into a bag; ``cbha_bag eval`` on it gives the RMS the demo printed.

A short demo (one small circle, open loop: ~15 s) runs as ``make demo`` runs it; the bag is then
evaluated by the ``cbha_bag eval`` command with the window the demo stored, and read by the
independent ``mcap`` + ``mcap-ros2-support`` reader (every recorded topic, the plant's valve
pressures among them).
"""

import json
import re
import subprocess
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
from ros_helpers import child_env, REPO_ROOT


def test_demo_bag_eval_gives_the_printed_rms(tmp_path):
    """Same RMS and max to 1e-6 mm; the bag has every recorded topic and decodes elsewhere."""
    output = tmp_path / 'demo'
    demo = subprocess.run(
        [sys.executable, '-m', 'cbha_inverse.ros.demo', '--output', str(output), '--shapes',
         'circle', '--modes', 'open', '--feedback', 'direct', '--radius', '0.005',
         '--start-hold', '0.5'],
        cwd=REPO_ROOT, env=child_env(), capture_output=True, text=True, timeout=240)
    assert demo.returncode == 0, demo.stdout + demo.stderr
    printed = float(re.search(r'circle open  : RMS +([0-9.]+) mm', demo.stdout).group(1))
    (run,) = json.loads((output / 'summary.json').read_text())['runs']
    assert run['rms_mm'] == pytest.approx(printed, abs=5e-4)  # printed with 3 decimals
    start, end = run['eval_window_s']
    evaluated = subprocess.run(
        [sys.executable, '-m', 'cbha_inverse.ros.bag_cli', 'eval', run['bag'], '--start',
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
                           '/cbha/pressure_command', '/cbha/pressure_measured', '/diagnostics'}
    assert all(len(message.data) == 6 for message in topics['/cbha/pressure_command'])
    # the plant's valve pressures (noise-free by default): within the commands' range
    commanded = np.array([message.data for message in topics['/cbha/pressure_command']])
    measured = np.array([message.data for message in topics['/cbha/pressure_measured']])
    assert measured.shape[1] == 6 and len(measured) > 100
    assert np.all(measured >= 0.0) and np.all(measured <= commanded.max(axis=0) + 1e-6)
    assert topics['/cbha/target'][0].header.frame_id == 'cbha_base'
