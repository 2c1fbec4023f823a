"""
``cbha_identify_check`` wiring: ``--excite`` reaches the demo, and cbha_identify gets both bags.

The steps are replaced by a recorder of their command lines (the real run takes minutes and is
the lead's end-to-end check); the nominal step writes the ``summary.json`` the demo writes, the
identified run then fails on purpose so that the check stops before it reads results.
"""

import json

from cbha_inverse.ros import identify_check


def _fake_steps(monkeypatch, tmp_path, excite_bag):
    commands = []

    def run(command, log):
        commands.append(list(command))
        if len(commands) == 1:          # the nominal demo run writes its summary
            nominal = tmp_path / 'nominal'
            nominal.mkdir(parents=True, exist_ok=True)
            summary = {'runs': []}
            if '--excite' in command:
                summary['excitation'] = {'bag': str(excite_bag)}
            (nominal / 'summary.json').write_text(json.dumps(summary))
        return 3 if len(commands) == 3 else 0

    monkeypatch.setattr(identify_check, '_run', run)
    return commands


def test_excite_is_recorded_and_identified_with_the_lap(monkeypatch, tmp_path):
    excite_bag = tmp_path / 'nominal' / 'excite_bends' / 'bag'
    commands = _fake_steps(monkeypatch, tmp_path, excite_bag)
    assert identify_check.main(['--output', str(tmp_path), '--excite', 'bends',
                                '--identify-args=--fit-latency']) == 3
    nominal, identification, identified = commands
    assert nominal[nominal.index('--excite') + 1] == 'bends'
    assert '--excite' not in identified
    assert identification == ['cbha_inverse.identify.cli',
                              str(tmp_path / 'nominal' / 'circle_open' / 'bag'), str(excite_bag),
                              '--output', str(tmp_path / 'identified'), '--fit-latency']


def test_without_excite_the_lap_alone(monkeypatch, tmp_path):
    commands = _fake_steps(monkeypatch, tmp_path, None)
    assert identify_check.main(['--output', str(tmp_path)]) == 3
    nominal, identification, _ = commands
    assert '--excite' not in nominal
    assert identification[:2] == ['cbha_inverse.identify.cli',
                                  str(tmp_path / 'nominal' / 'circle_open' / 'bag')]
    assert identification[2] == '--output'
