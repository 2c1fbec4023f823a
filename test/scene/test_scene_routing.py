"""
Cable routing forms of a scene: straight (the shorthand), helical and per-vertebra points.

Lengths against closed forms on the straight rest chain, the forms against each other, the
shipped scenes against the documented straight routing, and the twist a helix couples in.
"""

from pathlib import Path
import re
import shutil

from cbha_inverse.config_files import read_yaml
from cbha_inverse.core.actuation.cables import CableGroup
from cbha_inverse.core.so3 import so3_log
from cbha_inverse.errors import ConfigError
from cbha_inverse.paths import config_path
from cbha_inverse.scene import load_scene
import numpy as np
import pytest
import yaml

ROD_ROBOT = Path(__file__).resolve().parents[2] / 'docs' / 'examples' / 'rod_robot'
TENDON_SCENE = config_path('scenes', 'tendon_6f_8c.yaml')
GUIDE = Path(__file__).resolve().parents[2] / 'docs' / 'own-robot.md'
SHIPPED = sorted(config_path('scenes').glob('*.yaml')) + [ROD_ROBOT / 'rod_robot.yaml']


def _write_scene(directory, cables, name='routed', base=TENDON_SCENE, **changes):
    """Write ``base`` with other ``cables`` (and top-level ``changes``); return its path."""
    spec = read_yaml(base)
    spec.update(name=name, cables=cables, **changes)
    path = directory / f'{name}.yaml'
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return path


def _cables(scene):
    """Return the scene's cables in their group order."""
    return [cable for group in scene.actuators.groups if isinstance(group, CableGroup)
            for cable in group.cables]


def _vertebra_frames(spec, scene):
    """Frame of each vertebra: every ``beams_per_interval`` beams, or every segment frame."""
    chain = spec['chain']
    if chain['type'] == 'beam_vertebrae':
        return np.arange(chain['n_vertebrae'] + 1) * chain['beams_per_interval']
    return np.arange(scene.model.n_frames)


def _as_points(cable):
    """Rewrite a straight cable of a scene file as its per-vertebra ``points``."""
    start = cable.get('start_vertebra', 0)
    return {'name': cable['name'], 'max_tension': cable['max_tension'],
            'points': [{'vertebra': v, 'angle_deg': cable['angle_deg'],
                        'radius': cable['radius']}
                       for v in range(start, cable['end_vertebra'] + 1)]}


@pytest.fixture(scope='module')
def shipped_paths(tmp_path_factory):
    """Return the shipped scenes with cables, the guide's rod with its segment condensed (gmsh)."""
    from cbha_inverse.fem.cli import main as condense_main
    rod = tmp_path_factory.mktemp('rod_robot') / 'rod_robot'
    shutil.copytree(ROD_ROBOT, rod)
    condense_main([str(rod / 'rod_geometry.yaml'), '--output',
                   str(rod / 'segments' / 'rod_segment.yaml')])
    paths = [rod / 'rod_robot.yaml' if path.parent == ROD_ROBOT else path for path in SHIPPED]
    return [path for path in paths if 'cables' in read_yaml(path)]


def test_the_shipped_scenes_keep_their_straight_routing(shipped_paths, tmp_path):
    """
    Every shipped cable: through each vertebra up to its end at ``[0, r cos a, r sin a]``.

    And the same cables written as ``points`` or with a zero-pitch ``helix`` load to the very
    same routing (frames and offsets equal to the last bit).
    """
    assert {path.stem for path in shipped_paths} >= {'tendon_6f_8c', 'tendon_10f_16c',
                                                     'rod_robot'}
    for path in shipped_paths:
        spec = read_yaml(path)
        scene = load_scene(path)
        frames_of = _vertebra_frames(spec, scene)
        cables = _cables(scene)
        assert [c.name for c in cables] == [c['name'] for c in spec['cables']]
        for cable, item in zip(cables, spec['cables']):
            vertebrae = np.arange(item.get('start_vertebra', 0), item['end_vertebra'] + 1)
            angle = np.deg2rad(item['angle_deg'])
            np.testing.assert_array_equal(cable.frames, frames_of[vertebrae])
            np.testing.assert_allclose(
                cable.offsets, np.tile([0.0, item['radius'] * np.cos(angle),
                                        item['radius'] * np.sin(angle)], (vertebrae.size, 1)),
                rtol=0.0, atol=1e-18)
        rewritten = {
            'points': [_as_points(item) for item in spec['cables']],
            'helix': [{**item, 'helix': {'pitch_deg_per_vertebra': 0.0}}
                      for item in spec['cables']]}
        for form, items in rewritten.items():
            copy = _write_scene(path.parent if path.parent != config_path('scenes') else
                                tmp_path, items, name=f'{path.stem}_{form}', base=path)
            for cable, other in zip(cables, _cables(load_scene(copy))):
                np.testing.assert_array_equal(other.frames, cable.frames)
                np.testing.assert_array_equal(other.offsets, cable.offsets)


def test_the_guides_routing_example_loads_on_its_rod(shipped_paths):
    """The ``cables`` block of the guide's routing section, on the guide's six-segment rod."""
    section = GUIDE.read_text().split('### Cable routing', 1)[1]
    block = re.search(r'```yaml\n(cables:.*?)```', section, re.DOTALL).group(1)
    rod = next(path for path in shipped_paths if path.stem == 'rod_robot')
    scene = load_scene(_write_scene(rod.parent, yaml.safe_load(block)['cables'],
                                    name='rod_routed', base=rod))
    spiral, crossover = _cables(scene)
    np.testing.assert_allclose(np.rad2deg(np.arctan2(spiral.offsets[:, 2], spiral.offsets[:, 1])),
                               [0.0, 30.0, 60.0, 90.0, 120.0, 150.0], atol=1e-12)
    np.testing.assert_array_equal(crossover.frames, [0, 2, 4, 6])
    np.testing.assert_allclose(crossover.offsets[-1], [0.0, 0.0, 0.012])


@pytest.fixture(scope='module')
def tendon_spec():
    return read_yaml(TENDON_SCENE)


@pytest.fixture(scope='module')
def straight_rest(tendon_spec):
    """Return the tendon trunk's straight rest state (no gravity) and its vertebra spacing [m]."""
    scene = load_scene(TENDON_SCENE, gravity=[0.0, 0.0, 0.0])
    state = scene.forward(np.zeros(len(scene.actuator_names)), strict=True).state
    np.testing.assert_allclose(state.positions[:, 1:], 0.0, atol=1e-15)
    np.testing.assert_allclose(state.rotations, np.eye(3)[None].repeat(len(state.rotations), 0),
                               atol=1e-15)
    return state, tendon_spec['chain']['interval_length']


@pytest.mark.parametrize('pitch_deg, start, end', [
    (0.0, 0, 3), (25.0, 0, 3), (-40.0, 0, 3), (120.0, 1, 3), (90.0, 0, 2)])
def test_a_helix_on_the_straight_chain_is_its_chords(tmp_path, straight_rest, pitch_deg, start,
                                                     end):
    """Each span from vertebra to vertebra: ``sqrt(h² + (2 r sin(p/2))²)`` (chord of a helix)."""
    state, h = straight_rest
    radius = 0.012
    path = _write_scene(tmp_path, [
        {'name': 'helix', 'angle_deg': 30.0, 'radius': radius, 'end_vertebra': end,
         'start_vertebra': start, 'helix': {'pitch_deg_per_vertebra': pitch_deg},
         'max_tension': 10.0}], gravity=None)
    names, lengths, _ = load_scene(path).cable_lengths(state)
    chord = np.hypot(h, 2.0 * radius * np.sin(np.deg2rad(pitch_deg) / 2.0))
    assert names == ('helix',)
    assert lengths[0] == pytest.approx((end - start) * chord, rel=1e-12, abs=0.0)


def test_points_on_the_straight_chain_are_their_chords(tmp_path, straight_rest):
    """Mixed points (angle and radius, or an offset): the sum of the straight spans."""
    state, h = straight_rest
    points = [({'vertebra': 0, 'angle_deg': 10.0, 'radius': 0.01},
               [0.0, 0.01 * np.cos(np.deg2rad(10.0)), 0.01 * np.sin(np.deg2rad(10.0))]),
              ({'vertebra': 2, 'offset': [0.002, 0.0, -0.015]}, [0.002, 0.0, -0.015]),
              ({'vertebra': 3, 'angle_deg': 200.0, 'radius': 0.0},
               [0.0, 0.0, 0.0])]
    path = _write_scene(tmp_path, [{'name': 'mixed', 'max_tension': 10.0,
                                    'points': [point for point, _ in points]}], gravity=None)
    _, lengths, _ = load_scene(path).cable_lengths(state)
    positions = np.array([[h * point['vertebra'], 0.0, 0.0] for point, _ in points])
    positions += np.array([offset for _, offset in points])
    expected = np.linalg.norm(np.diff(positions, axis=0), axis=1).sum()
    assert lengths[0] == pytest.approx(expected, rel=1e-12, abs=0.0)


def test_points_equal_to_the_straight_form_give_its_lengths_and_forces(tmp_path, tendon_spec):
    """The trunk's tendons as ``points``: same lengths and same equilibria (actuation columns)."""
    shorthand = load_scene(TENDON_SCENE)
    path = _write_scene(tmp_path, [_as_points(item) for item in tendon_spec['cables']])
    points = load_scene(path)
    assert points.actuator_names == shorthand.actuator_names
    tension = np.linspace(0.5, 6.0, len(shorthand.actuator_names))
    reference = shorthand.forward(tension, strict=True)
    result = points.forward(tension, strict=True)
    np.testing.assert_allclose(result.effector_positions, reference.effector_positions,
                               rtol=0.0, atol=1e-15)
    for state in (reference.state, result.state):
        np.testing.assert_array_equal(points.cable_lengths(state)[1],
                                      shorthand.cable_lengths(state)[1])
        np.testing.assert_array_equal(points.cable_lengths(state)[2],
                                      shorthand.cable_lengths(state)[2])


@pytest.fixture(scope='module')
def helix_scene(tmp_path_factory):
    """Four helical tendons (30 deg per vertebra, 90 deg in all) and a straight one, no gravity."""
    cables = [{'name': f'helix_{a}', 'angle_deg': float(a), 'radius': 0.012, 'end_vertebra': 3,
               'helix': {'pitch_deg_per_vertebra': 30.0}, 'max_tension': 10.0}
              for a in (0, 90, 180, 270)]
    cables.append({'name': 'straight_0', 'angle_deg': 0.0, 'radius': 0.012, 'end_vertebra': 3,
                   'max_tension': 10.0})
    return load_scene(_write_scene(tmp_path_factory.mktemp('helix'), cables, gravity=None))


def test_a_helix_bends_out_of_the_straight_tendons_plane_and_twists(helix_scene):
    """
    A straight tendon at +y bends the tip in the x-y plane, no twist (the chain's symmetry).

    The helical tendon from the same hole ends at 90 deg (+z): its tip leaves that plane, and
    its tension, wound around the backbone, twists the tip about its axis.
    """
    names = helix_scene.actuator_names
    rest = helix_scene.rest_effector_positions[-1]
    moves, twists = {}, {}
    for name in ('straight_0', 'helix_0'):
        tension = np.where(np.array(names) == name, 5.0, 0.0)
        result = helix_scene.forward(tension, strict=True)
        moves[name] = result.effector_positions[-1] - rest
        twists[name] = so3_log(result.state.rotations[-1])[0]
    straight, helix = moves['straight_0'], moves['helix_0']
    assert np.linalg.norm(straight) > 5e-3
    assert abs(straight[2]) < 1e-9 * np.linalg.norm(straight)
    assert abs(twists['straight_0']) < 1e-9
    # out of the plane by a good share of the move (it bends between +y and +z)
    assert abs(helix[2]) > 0.2 * np.linalg.norm(helix)
    assert abs(twists['helix_0']) > 1e-3


def test_the_inverse_reaches_a_target_of_helical_tendons(helix_scene):
    """A forward solve of the helical tendons gives a target; the inverse converges onto it."""
    tension = np.array([4.0, 1.5, 0.0, 0.0, 0.0])
    target = helix_scene.forward(tension, strict=True).effector_positions
    solver = helix_scene.make_inverse_solver()
    statuses = []
    for _ in range(30):
        out = solver.step(target)
        statuses.append(out.status)
    assert set(statuses[-5:]) <= {'solved', 'saturated'}, statuses
    assert np.abs(out.effector_positions - target).max() < 5e-4
    reached = helix_scene.forward(out.actuation, strict=True).effector_positions
    assert np.abs(reached - out.effector_positions).max() < 5e-4


_HELIX = {'name': 'c', 'angle_deg': 0.0, 'radius': 0.012, 'end_vertebra': 3,
          'max_tension': 10.0}
_POINTS = {'name': 'c', 'max_tension': 10.0,
           'points': [{'vertebra': 0, 'angle_deg': 0.0, 'radius': 0.012},
                      {'vertebra': 2, 'angle_deg': 45.0, 'radius': 0.012}]}


def _point_edit(index, **changes):
    """Return ``_POINTS`` with point ``index`` changed (None removes a key)."""
    points = [dict(point) for point in _POINTS['points']]
    points[index].update(changes)
    points[index] = {k: v for k, v in points[index].items() if v is not None}
    return {**_POINTS, 'points': points}


@pytest.mark.parametrize('cable, key, problem', [
    (_point_edit(1, vertebra=0), 'cables[0].points[1].vertebra',
     "0 must lie above the previous point's 0"),
    (_point_edit(1, vertebra=4), 'cables[0].points[1].vertebra', '4 outside 0..3'),
    (_point_edit(0, vertebra=-1), 'cables[0].points[0].vertebra', 'must be >= 0'),
    (_point_edit(1, radius=-0.01), 'cables[0].points[1].radius', 'must be >= 0, got -0.01'),
    (_point_edit(1, offset=[0.0, 0.01, 0.0]), 'cables[0].points[1].angle_deg',
     'give offset or angle_deg and radius, not both'),
    (_point_edit(1, offset=[0.0, 0.01], angle_deg=None, radius=None),
     'cables[0].points[1].offset',
     'must be a list of 3 finite numbers'),
    (_point_edit(1, vertebrae=3, vertebra=None), 'cables[0].points[1].vertebrae',
     "unknown key, did you mean 'vertebra'?"),
    ({**_POINTS, 'points': _POINTS['points'][:1]}, 'cables[0].points',
     'a cable needs >= 2 routing points, got 1'),
    ({**_POINTS, 'angle_deg': 0.0}, 'cables[0].angle_deg',
     'give points or the straight form (angle_deg, radius, end_vertebra), not both'),
    ({**_POINTS, 'helix': {'pitch_deg_per_vertebra': 30.0}}, 'cables[0].helix',
     'give points or the straight form'),
    ({**_POINTS, 'pionts': _POINTS['points']}, 'cables[0].pionts',
     "unknown key, did you mean 'points'?"),
    ({**_HELIX, 'radius': -0.012}, 'cables[0].radius', 'must be > 0, got -0.012'),
    ({**_HELIX, 'helix': {'pitch_deg_per_vertebrae': 30.0}},
     'cables[0].helix.pitch_deg_per_vertebrae',
     "unknown key, did you mean 'pitch_deg_per_vertebra'?"),
    ({**_HELIX, 'helix': {}}, 'cables[0].helix.pitch_deg_per_vertebra', 'missing'),
    ({**_HELIX, 'helix': 30.0}, 'cables[0].helix', 'must be a mapping of keys, got float'),
    ({**_HELIX, 'helx': {'pitch_deg_per_vertebra': 30.0}}, 'cables[0].helx',
     "unknown key, did you mean 'helix'?"),
    ({**_HELIX, 'end_vertebra': 4, 'helix': {'pitch_deg_per_vertebra': 30.0}},
     'cables[0].end_vertebra', '4 outside 1..3'),
    ({**_HELIX, 'axial_stiffness': 0.0}, 'cables[0].axial_stiffness', 'must be > 0, got 0'),
    ({**_HELIX, 'axial_stifness': 4e3}, 'cables[0].axial_stifness',
     "unknown key, did you mean 'axial_stiffness'?"),
])
def test_a_wrong_route_is_one_line_naming_its_key(tmp_path, cable, key, problem):
    path = _write_scene(tmp_path, [cable])
    with pytest.raises(ConfigError) as info:
        load_scene(path)
    assert (info.value.path, info.value.key) == (str(path), key)
    assert info.value.problem.startswith(problem), info.value.problem
    assert '\n' not in str(info.value)
