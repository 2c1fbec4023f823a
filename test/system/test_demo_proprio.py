"""
``cbha_demo --feedback proprio``: the closed loop on the string-pot estimate, no tip measured.

A short demo (one small circle) with a plant whose cavity gains the model does not know: the run
records no ``tip/measured`` at all, ``tip/estimated`` and ``string_pots`` instead, tracks the
circle and prints the estimate's own RMS against ``tip/true``.
"""

import json
import re
import subprocess
import sys

from cbha_inverse.experiments.proprio import estimate_error
from mcap.reader import make_reader
import pytest
from ros_helpers import child_env, REPO_ROOT


def test_demo_closes_the_loop_on_the_string_pots(tmp_path):
    output = tmp_path / 'demo'
    demo = subprocess.run(
        [sys.executable, '-m', 'cbha_inverse.experiments.demo', '--output', str(output),
         '--feedback', 'proprio', '--proprio-shapes', 'circle', '--radius', '0.01',
         '--start-hold', '1.0', '--stiffness-scale', '1.0',
         '--plant-gain-scale', '1.1,0.9,1.05,0.92,1.08,0.95'],
        cwd=REPO_ROOT, env=child_env(), capture_output=True, text=True, timeout=240)
    assert demo.returncode == 0, demo.stdout + demo.stderr
    assert re.search(r'circle proprio: RMS +[0-9.]+ mm', demo.stdout), demo.stdout
    estimated = float(re.search(r'estimated tip vs true RMS ([0-9.]+) mm', demo.stdout).group(1))
    (run,) = json.loads((output / 'summary.json').read_text())['runs']
    assert run['feedback'] == 'proprio' and run['rms_mm'] < 3.0, run
    assert estimated < 2.0
    topics = set()
    for file in sorted((output / 'circle_closed_proprio' / 'bag').glob('*.mcap')):
        with open(file, 'rb') as stream:
            for _, channel, _ in make_reader(stream).iter_messages():
                topics.add(channel.topic)
    assert '/cbha/tip/measured' not in topics
    assert {'/cbha/tip/estimated', '/cbha/string_pots', '/cbha/tip/true'} <= topics


class _Recorded:
    targets = [(10.0, 0.0, 0.0, 0.0)]
    tips = [(10.0, 0.0, 0.0, 0.0), (11.0, 1.0, 0.0, 0.0), (12.0, 0.0, 0.0, 0.0)]
    estimated = [(10.0, 0.0, 0.0, 5.0), (11.0, 1.0, 0.003, 0.004), (12.0, 0.0, 0.0, 0.001),
                 (11.5, 0.5, 0.0, 0.002), (12.25, 9.0, 9.0, 9.0)]


@pytest.mark.untimed
def test_estimate_error_interpolates_the_true_tip_in_the_window():
    # the sample at 10 s is before the window, the one at 12.25 s after the last true tip; at
    # 11.5 s the true tip is halfway between those of 11 s and 12 s
    expected = ((0.005 ** 2 + 0.001 ** 2 + 0.002 ** 2) / 3) ** 0.5
    assert abs(estimate_error(_Recorded, 0.5, 2.5) - expected) < 1e-12


@pytest.mark.untimed
def test_the_estimated_sections_go_into_the_solver_unless_told_not():
    """--estimate-sections sets the estimator's priors and the solver's section topic."""
    from cbha_inverse.experiments.demo import parse_args
    from cbha_inverse.experiments.proprio import proprio_node_parameters
    estimator, solver = proprio_node_parameters(parse_args(['--estimate-sections', '0.2,0.1']))
    assert estimator['section_stiffness_std'] == 0.2 and estimator['gain_std'] == 0.1
    assert solver['section_stiffness_topic'] == 'sections/estimated'
    assert solver['payload_topic'] == '' and 'max_section_change' not in solver
    _, solver = proprio_node_parameters(parse_args(['--estimate-sections', '0.2',
                                                    '--no-feed-sections']))
    assert solver['section_stiffness_topic'] == ''
    _, solver = proprio_node_parameters(parse_args(['--max-section-change', '0.01']))
    assert solver['section_stiffness_topic'] == '' and solver['max_section_change'] == 0.01
    estimator, solver = proprio_node_parameters(parse_args(['--feed-gains']))
    assert estimator['publish_gains'] and solver['actuator_gain_topic'] == 'gains/estimated'
    _, solver = proprio_node_parameters(parse_args(['--proprio-max-correction', '0.06']))
    assert solver['max_correction'] == 0.06
