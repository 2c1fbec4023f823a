"""``cbha_report stability --quick``: every case passes, the files are written."""

import json

from cbha_inverse.report.cli import main as report_main


def test_quick_stability_report_passes_every_case(tmp_path):
    """A case that regresses (a wrong answer without a message) fails this test."""
    code = report_main(['stability', '--quick', '--output', str(tmp_path)])
    summary = json.loads((tmp_path / 'stability.json').read_text(encoding='utf-8'))
    failed = [f"{c['group']}: {c['name']} ({c['message']})" for c in summary['cases']
              if not c['passed']]
    assert failed == [] and code == 0
    groups = {c['group'] for c in summary['cases']}
    assert groups == {'stiffness ratio', 'Poisson ratio', 'segment length', 'frames', 'roll-up',
                      'large load', 'buckling', 'actuators', 'targets', 'contact',
                      'random robots'}
    assert (tmp_path / 'stability.png').stat().st_size > 10000
    assert 'message to the user' in (tmp_path / 'stability.md').read_text(encoding='utf-8')
