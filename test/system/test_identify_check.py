"""
``cbha_identify_check`` wiring: ``--excite`` reaches the demo, and cbha_identify gets both bags.

The steps' command lines are built by :func:`check_steps` (the real run takes minutes and is
the lead's end-to-end check); the nominal run's ``summary.json`` is written here as the demo
writes it.
"""

import json

from cbha_inverse.experiments.identify_check import check_steps, parse_args


def _commands(tmp_path, argv, excite_bag=None):
    steps = check_steps(parse_args(['--output', str(tmp_path), *argv]), tmp_path)
    labels = [label for label, _ in steps]
    assert labels == ['nominal runs', 'identification', 'identified run']
    nominal = steps[0][1]()
    summary = {'runs': []}
    if excite_bag is not None:
        summary['excitation'] = {'bag': str(excite_bag)}
    (tmp_path / 'nominal').mkdir()
    (tmp_path / 'nominal' / 'summary.json').write_text(json.dumps(summary))
    return nominal, steps[1][1](), steps[2][1]()


def test_excite_is_recorded_and_identified_with_the_lap(tmp_path):
    excite_bag = tmp_path / 'nominal' / 'excite_bends' / 'bag'
    nominal, identification, identified = _commands(
        tmp_path, ['--excite', 'bends', '--identify-args=--fit-latency', '--seed', '7'],
        excite_bag)
    assert nominal[nominal.index('--excite') + 1] == 'bends'
    assert nominal[nominal.index('--plant-seed') + 1] == '7'
    assert '--excite' not in identified
    assert identification == ['cbha_inverse.identify.cli',
                              str(tmp_path / 'nominal' / 'circle_open' / 'bag'), str(excite_bag),
                              '--output', str(tmp_path / 'identified'), '--fit-latency']
    assert identified[identified.index('--model-scene') + 1] == str(
        tmp_path / 'identified' / 'cbha_identified.yaml')


def test_without_excite_the_lap_alone(tmp_path):
    nominal, identification, _ = _commands(tmp_path, [])
    assert '--excite' not in nominal
    assert identification == ['cbha_inverse.identify.cli',
                              str(tmp_path / 'nominal' / 'circle_open' / 'bag'),
                              '--output', str(tmp_path / 'identified')]


def test_a_plant_base_offset_is_applied_and_fitted(tmp_path):
    nominal, identification, identified = _commands(
        tmp_path, ['--plant-base-offset', '0.002,-0.003,0.001'])
    for command in (nominal, identified):
        assert command[command.index('--plant-base-offset') + 1] == '0.002,-0.003,0.001'
    assert '--fit-base-position' in identification


def test_the_plants_pots_and_the_camera_less_runs(tmp_path):
    from cbha_inverse.experiments.demo import _sim_overrides, parse_args as demo_args
    pots = ['--plant-pot-offset', '3,-2,1.5,-4,2.5,-1', '--plant-pot-gain', '1020']
    steps = check_steps(parse_args(['--output', str(tmp_path), '--proprio', *pots]), tmp_path)
    assert [label for label, _ in steps][3:] == [
        'camera-less reference', 'camera-less uncalibrated', 'camera-less identified']
    nominal = demo_args(steps[0][1]()[1:])
    offsets = _sim_overrides(nominal, ['v'])['string_pot_offset']
    assert offsets == [3.0, -2.0, 1.5, -4.0, 2.5, -1.0]
    assert _sim_overrides(nominal, ['v'])['string_pot_gain'] == [1020.0]
    reference, uncalibrated, identified = (demo_args(command()[1:]) for _, command in steps[3:])
    for run in (reference, uncalibrated, identified):
        assert (run.modes, run.feedback, run.proprio_shapes) == ('closed', 'proprio',
                                                                 'circle,square')
    assert 'string_pot_offset' not in _sim_overrides(reference, ['v'])
    assert reference.model_scene is None and uncalibrated.model_scene is None
    assert uncalibrated.plant_pot_gain == identified.plant_pot_gain == '1020'
    assert identified.model_scene == str(tmp_path / 'identified' / 'cbha_identified.yaml')
