"""
``cbha_scene check --actuation`` and ``--convergence`` against references computed here.

The equilibrium printed by ``--actuation`` is :meth:`Scene.forward` at that actuation, its tendon
length changes those of :meth:`Scene.cable_lengths`, its string pots those of ``scene.sensors``;
the tip movement printed by ``--convergence`` is the difference of two forward solves on scene
files refined here by editing their text (``beams_per_interval``, or a segment recondensed at
half its mesh size); the guide's excerpt of both options is what the commands print.
"""

from pathlib import Path
import re
import shlex
import shutil

from cbha_inverse.fem.cli import main as condense_main
from cbha_inverse.fem.segment_io import load_segment
from cbha_inverse.paths import config_path
from cbha_inverse.scene import load_scene
from cbha_inverse.scene.cli import main
from cbha_inverse.scene.refinement import load_data, refined_beam_data, scene_data
import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
TENDON = config_path('scenes', 'tendon_6f_8c.yaml')
MM = 5e-7
"""Half the last printed digit of a length in mm [m]."""


def _numbers(text):
    return [float(v) for v in re.findall(r'[-+]?\d+\.\d+', text)]


def _run(capsys, *args):
    status = main(['check', *map(str, args)])
    return status, capsys.readouterr().out


@pytest.fixture(scope='module')
def tendon():
    return load_scene(TENDON)


def test_actuation_prints_the_forward_equilibrium_and_tendon_lengths(capsys, tendon):
    actuation = np.array([5.0, 0.0, 0.0, 1.5, 2.0, 0.0, 0.0, 7.0])
    status, out = _run(capsys, 'tendon_6f_8c', '--actuation', *actuation)
    assert status == 0, out
    result = tendon.forward(actuation)
    rest = tendon.forward(np.zeros(8))
    assert result.converged
    lines = out.splitlines()
    start = lines.index('equilibrium at [5, 0, 0, 1.5, 2, 0, 0, 7] N:')
    assert lines[start + 1].startswith(f'  converged: {result.iterations} iterations')
    tip = _numbers(lines[start + 2].split('effector tip: ')[1])
    np.testing.assert_allclose(1e-3 * np.array(tip[:3]), result.effector_positions[0], atol=MM)
    moved = result.effector_positions[0] - rest.effector_positions[0]
    np.testing.assert_allclose(1e-3 * np.array(tip[3:6]), moved, atol=MM)
    names, lengths, _ = tendon.cable_lengths(result.state)
    _, rest_lengths, _ = tendon.cable_lengths(rest.state)
    table = lines[lines.index('tendon lengths (routed; change from rest, pulled in: negative):')
                  + 1:]
    assert [line.split(':')[0].strip() for line in table] == list(names)
    printed = 1e-3 * np.array([_numbers(line) for line in table])
    np.testing.assert_allclose(printed[:, 0], lengths, atol=MM)
    np.testing.assert_allclose(printed[:, 1], lengths - rest_lengths, atol=MM)
    # the tendon pulled hardest is pulled in, the one opposite it let out
    assert printed[0, 1] < 0.0 < printed[2, 1]


def test_actuation_fraction_is_that_fraction_of_every_range(capsys):
    _, by_fraction = _run(capsys, 'tendon_6f_8c', '--actuation-fraction', 0.25)
    _, by_values = _run(capsys, 'tendon_6f_8c', '--actuation', *[2.5] * 8)
    start = by_fraction.index('equilibrium at')
    assert by_fraction[start:] == by_values[by_values.index('equilibrium at'):]
    assert 'reach' not in by_fraction and 'tick' not in by_fraction


def test_actuation_prints_the_string_pots(capsys, tmp_path):
    path = tmp_path / 'with_pots.yaml'
    path.write_text(TENDON.read_text() + (
        '\nsensors:\n'
        '  - {name: pot_a, kind: string_pot, angle_deg: 90.0, radius: 0.01, end_vertebra: 3,\n'
        '     offset: 5.0, gain: 1000.0}\n'
        '  - {name: pot_b, kind: string_pot, angle_deg: 0.0, radius: 0.01, end_vertebra: 2,\n'
        '     offset: -2.0, gain: 2000.0}\n'))
    scene = load_scene(path)
    actuation = np.array([0.0, 6.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    status, out = _run(capsys, path, '--actuation', *actuation)
    assert status == 0, out
    state = scene.forward(actuation).state
    rest = scene.forward(np.zeros(8)).state
    lengths = scene.sensors.lengths(state.positions, state.rotations)
    changes = lengths - scene.sensors.lengths(rest.positions, rest.rotations)
    lines = out.splitlines()
    table = lines[lines.index('string pots (length, change from rest; raw reading):') + 1:]
    assert [line.split(':')[0].strip() for line in table] == ['pot_a', 'pot_b']
    printed = np.array([_numbers(line) for line in table])
    np.testing.assert_allclose(1e-3 * printed[:, 0], lengths, atol=MM)
    np.testing.assert_allclose(1e-3 * printed[:, 1], changes, atol=MM)
    np.testing.assert_allclose(printed[:, 2], scene.sensors.readings(lengths), rtol=1e-5)
    # the pot on the side of the pulled tendon shortens
    assert printed[0, 1] < 0.0


@pytest.mark.parametrize('args, message', [
    (['--actuation', '1', '2'], '--actuation needs 8 values, one per actuator (tip_0, tip_90, '
     'tip_180, tip_270, mid_45, mid_135, mid_225, mid_315), got 2'),
    (['--actuation', '1', '2', '3', '4', '5', '6', '7', '12'],
     '--actuation: mid_315 12 N is outside its bounds [0, 10] N'),
    (['--actuation', '-1', '2', '3', '4', '5', '6', '7', '12'],
     '--actuation: tip_0 -1 N is outside its bounds [0, 10] N (and 1 more)'),
    (['--actuation-fraction', '1.5'], '--actuation-fraction must lie in [0, 1], got 1.5'),
    (['--recondense'], '--recondense needs --convergence'),
])
def test_a_bad_actuation_is_one_line_and_exit_2(capsys, args, message):
    with pytest.raises(SystemExit) as info:
        main(['check', 'tendon_6f_8c', *args])
    assert info.value.code == 2
    captured = capsys.readouterr()
    assert captured.out == ''
    assert captured.err.splitlines()[-1] == f'cbha_scene: error: {message}'


def _movement(out, label):
    return 1e-3 * float(re.search(rf'^  {label}: tip moves (\S+) mm$', out, re.MULTILINE)[1])


def test_convergence_of_the_tendon_scene_is_two_forward_solves(capsys, tmp_path, tendon):
    status, out = _run(capsys, 'tendon_6f_8c', '--convergence')
    assert status == 0, out
    # the reference: the scene file with 4 beams per interval, edited here as text
    text = TENDON.read_text()
    assert text.count('beams_per_interval: 2 ') == 1
    fine_path = tmp_path / 'fine.yaml'
    fine_path.write_text(text.replace('beams_per_interval: 2 ', 'beams_per_interval: 4 '))
    fine = load_scene(fine_path)
    assert fine.model.n_links == 2 * tendon.model.n_links
    half = 0.5 * tendon.upper_bounds
    for label, actuation in (('rest', np.zeros(8)), ('half range', half)):
        expected = np.linalg.norm(fine.forward(actuation, strict=True).effector_positions[0]
                                  - tendon.forward(actuation, strict=True).effector_positions[0])
        np.testing.assert_allclose(_movement(out, label), expected, atol=MM)
    assert 'convergence: beams_per_interval 2 -> 4' in out
    worst = max(_movement(out, 'rest'), _movement(out, 'half range'))
    assert out.splitlines()[-1] == (f'  refine: beams_per_interval 4 moves the effectors '
                                    f'{1e3 * worst:.3f} mm, above 0.1 mm (use it, and check '
                                    'again)')
    quoted = re.search(r'`(refine: beams_per_interval [^`]+)`',
                       (REPO / 'docs' / 'own-robot.md').read_text())[1]
    assert quoted in out, (quoted, out)
    status, out = _run(capsys, 'tendon_6f_8c', '--convergence', '--tolerance', 2)
    assert out.splitlines()[-1].startswith('  converged: beams_per_interval 4 moves the '
                                           'effectors')


def test_convergence_at_the_given_actuation_too(capsys, tendon):
    actuation = [0.0, 0.0, 8.0, 0.0, 0.0, 3.0, 0.0, 0.0]
    status, out = _run(capsys, 'tendon_6f_8c', '--convergence', '--actuation', *actuation)
    assert status == 0, out
    fine = load_scene_refined(tendon)
    expected = np.linalg.norm(fine.forward(actuation).effector_positions[0]
                              - tendon.forward(actuation).effector_positions[0])
    np.testing.assert_allclose(_movement(out, 'given actuation'), expected, atol=MM)


def load_scene_refined(scene):
    """Return ``scene`` with twice its beams per interval, through the refinement module."""
    from cbha_inverse.scene.refinement import refined_beam_scene
    return refined_beam_scene(scene.path)[0]


def test_an_effector_on_a_frame_index_stays_on_its_point_of_the_backbone(tmp_path):
    path = tmp_path / 'frames.yaml'
    path.write_text(TENDON.read_text().replace(
        '  - {name: tip, vertebra: 3, offset: [0.0, 0.0, 0.0]}',
        '  - {name: by_frame, frame: 4, offset: [0.0, 0.0, 0.01]}\n'
        '  - {name: tip, vertebra: 3, offset: [0.0, 0.0, 0.0]}'))
    data = refined_beam_data(scene_data(path))
    assert data['effectors'][0] == {'name': 'by_frame', 'frame': 8, 'offset': [0.0, 0.0, 0.01]}
    assert data['effectors'][1]['vertebra'] == 3 and data['chain']['beams_per_interval'] == 4
    # without gravity or actuation the backbone is straight: frame 4 of 6 is frame 8 of 12
    scene = load_scene(path, gravity=[0.0, 0.0, 0.0])
    data['gravity'] = None
    refined = load_data(data, tmp_path, 'refined.yaml')
    assert refined.model.n_links == 12
    for straight in (scene, refined):
        np.testing.assert_allclose(straight.rest_effector_positions[0], [0.08, 0.0, 0.01],
                                   atol=1e-12)


def test_convergence_of_a_segments_scene_prints_the_recondensing_commands(capsys):
    status, out = _run(capsys, 'cbha', '--convergence')
    assert status == 0, out
    segment = load_segment(config_path('segments', 'cbha_segment.yaml'))
    size = segment.metadata['mesh_size']
    assert re.search(rf'cbha_segment.yaml \(sections inner, outer\): P2, mesh size '
                     rf'{1e3 * size:g} mm, .*; geometry .*meshes/cbha_segment_geometry.yaml$',
                     out, re.MULTILINE), out
    assert re.search(rf'^  condense_segment .*meshes/cbha_segment_geometry.yaml --order 2 '
                     rf'--mesh-size {size / 2:g} --output fine_0/cbha_segment.yaml$', out,
                     re.MULTILINE), out
    assert out.splitlines()[-1].startswith('convergence: not checked')


@pytest.fixture(scope='module')
def rod(tmp_path_factory):
    """Copy the guide's example robot (docs/examples/rod_robot) and condense its segment."""
    work = tmp_path_factory.mktemp('rod') / 'my_robot'
    shutil.copytree(REPO / 'docs' / 'examples' / 'rod_robot', work)
    assert condense_main([str(work / 'rod_geometry.yaml'), '--output',
                          str(work / 'segments' / 'rod_segment.yaml')]) == 0
    return work


def test_recondense_is_two_forward_solves_on_the_two_meshes(capsys, rod, tmp_path,
                                                            monkeypatch):
    monkeypatch.chdir(rod)
    status, out = _run(capsys, 'rod_robot.yaml', '--convergence', '--recondense')
    assert status == 0, out
    # the reference: condense_segment at half the mesh size, and a scene file naming it
    fine_dir = tmp_path / 'fine'
    assert condense_main([str(rod / 'rod_geometry.yaml'), '--mesh-size', '0.002', '--output',
                          str(fine_dir / 'rod_segment.yaml')]) == 0
    capsys.readouterr()
    scene_text = (rod / 'rod_robot.yaml').read_text()
    fine_path = tmp_path / 'rod_fine.yaml'
    fine_path.write_text(scene_text.replace('segment: segments/rod_segment.yaml',
                                            f'segment: {fine_dir / "rod_segment.yaml"}'))
    coarse, fine = load_scene(rod / 'rod_robot.yaml'), load_scene(fine_path)
    assert 'convergence: mesh_size 4 mm -> 2 mm' in out
    for label, actuation in (('rest', np.zeros(4)), ('half range', np.full(4, 5.0))):
        expected = np.linalg.norm(fine.forward(actuation, strict=True).effector_positions[0]
                                  - coarse.forward(actuation, strict=True).effector_positions[0])
        np.testing.assert_allclose(_movement(out, label), expected, atol=MM)


def _guide_excerpt():
    """Return the guide's commands and output lines of the two options, from its text block."""
    text = (REPO / 'docs' / 'own-robot.md').read_text()
    block = re.search(r'```text\n(\$ cbha_scene check .*?)```', text, re.DOTALL)[1]
    runs = []
    for line in block.splitlines():
        if line.startswith('$ '):
            runs.append((shlex.split(line[2:]), []))
        elif line.strip() != '...':
            runs[-1][1].append(line)
    return runs


def _untimed(line):
    return re.sub(r'\d+\.\d+ s\b', 'T s', line)


def test_the_guide_excerpt_is_what_the_commands_print(capsys, rod, monkeypatch):
    monkeypatch.chdir(rod)
    runs = _guide_excerpt()
    assert [command[:2] for command, _ in runs] == [['cbha_scene', 'check']] * len(runs)
    for command, shown in runs:
        status, out = _run(capsys, *command[2:])
        assert status == 0, out
        printed = [_untimed(line) for line in out.splitlines()]
        for line in shown:
            assert _untimed(line) in printed, f'{shlex.join(command)} did not print:\n{line}'
