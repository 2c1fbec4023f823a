"""
The sampled reachable set of a scene, ``workspace_center: reachable_center`` and its check.

References independent of :mod:`cbha_inverse.scene.reach`: cold strict forward solves of every
sample, scipy's Delaunay point-in-hull test (no half-spaces), a brute-force search of the largest
circle around every sample by bisection, the closed-form arc of a rod bent by one tendon without
gravity, and the inverse solver reaching the reported circle.
"""

import re

from cbha_inverse.errors import ConfigError
from cbha_inverse.paths import config_path
from cbha_inverse.scene import load_scene
from cbha_inverse.scene import reach as reach_module
from cbha_inverse.scene.cli import main
from cbha_inverse.scene.reach import fewest_samples, PLANES, sample_reachable_set
import numpy as np
import pytest
from scipy.spatial import Delaunay

SAMPLES = 60
ANGLES = np.linspace(0.0, 2.0 * np.pi, 360, endpoint=False)

# a rod of 12 Timoshenko beams (0.12 m) and four tendons to the tip, no gravity: one tendon at
# tension T bends it into an arc of curvature T r / (E I), shortened by T / (E A)
ARC_ROD = """\
name: arc_rod
gravity: [0.0, 0.0, 0.0]
chain:
  type: beam_vertebrae
  n_vertebrae: 6
  beams_per_interval: 2
  interval_length: 0.02
  backbone: {youngs_modulus: 2.0e+7, poisson_ratio: 0.45, outer_radius: 0.006, density: 1100.0}
cables:
  - {name: c0, angle_deg: 0.0, radius: 0.012, end_vertebra: 6, max_tension: 5.0}
  - {name: c90, angle_deg: 90.0, radius: 0.012, end_vertebra: 6, max_tension: 5.0}
  - {name: c180, angle_deg: 180.0, radius: 0.012, end_vertebra: 6, max_tension: 5.0}
  - {name: c270, angle_deg: 270.0, radius: 0.012, end_vertebra: 6, max_tension: 5.0}
effectors:
  - {name: tip, vertebra: 6, offset: [0.0, 0.0, 0.0]}
"""
ARC = {'length': 0.12, 'E': 2.0e7, 'radius': 0.006, 'arm': 0.012, 'max_tension': 5.0}


def _scene_file(tmp_path, text, name='scene.yaml'):
    path = tmp_path / name
    path.write_text(text)
    return path


def _tendon_text(workspace):
    text = config_path('scenes', 'tendon_6f_8c.yaml').read_text()
    old = 'workspace_center: {actuation_fraction: 0.3}'
    assert old in text
    return text.replace(old, f'workspace_center: {workspace}')


@pytest.fixture(scope='module')
def tendon():
    return load_scene('tendon_6f_8c')


@pytest.fixture(scope='module')
def tendon_reach(tendon):
    return sample_reachable_set(tendon, SAMPLES)


@pytest.fixture(scope='module')
def arc_rod(tmp_path_factory):
    return load_scene(_scene_file(tmp_path_factory.mktemp('arc'), ARC_ROD))


def _circle(center, radius, plane):
    """Return points (len(ANGLES), 3) of a circle in ``plane`` through ``center``."""
    a, b = PLANES[plane]
    points = np.tile(np.asarray(center, dtype=float), (len(ANGLES), 1))
    points[:, a] += radius * np.cos(ANGLES)
    points[:, b] += radius * np.sin(ANGLES)
    return points


def _inside(hull, points):
    return hull.find_simplex(points) >= 0


def _largest_circle(hull, centers, plane, top):
    """Return, by bisection, the largest circle around each centre inside the Delaunay hull."""
    low, high = np.zeros(len(centers)), np.full(len(centers), top)
    for _ in range(30):
        middle = 0.5 * (low + high)
        ok = np.array([np.all(_inside(hull, _circle(c, r, plane))) if _inside(hull, c[None])[0]
                       else False for c, r in zip(centers, middle)])
        low = np.where(ok, middle, low)
        high = np.where(ok, high, middle)
    return low


def test_every_sample_is_a_converged_forward_solve_within_the_bounds(tendon, tendon_reach):
    reach = tendon_reach
    assert reach.failed == 0 and reach.effector == 'tip'
    assert reach.actuations.shape == (SAMPLES, 8) and reach.points.shape == (SAMPLES, 3)
    assert np.all(reach.actuations >= tendon.lower_bounds)
    assert np.all(reach.actuations <= tendon.upper_bounds)
    # the lower bounds and each actuator alone at its upper bound are sampled
    assert any(np.array_equal(a, tendon.lower_bounds) for a in reach.actuations)
    for k in range(8):
        alone = tendon.lower_bounds.copy()
        alone[k] = tendon.upper_bounds[k]
        assert any(np.array_equal(a, alone) for a in reach.actuations), k
    for actuation, point in zip(reach.actuations, reach.points):
        cold = tendon.forward(actuation, strict=True).effector_positions[-1]
        np.testing.assert_allclose(point, cold, atol=1e-7)


def test_the_box_is_the_extent_of_the_samples(tendon_reach):
    reach = tendon_reach
    assert np.all(reach.points >= reach.box_min) and np.all(reach.points <= reach.box_max)
    for axis in range(3):
        assert np.isclose(reach.points[:, axis].min(), reach.box_min[axis])
        assert np.isclose(reach.points[:, axis].max(), reach.box_max[axis])


def test_the_circles_lie_inside_the_hull_of_the_samples_and_are_maximal(tendon_reach):
    reach = tendon_reach
    hull = Delaunay(reach.points)
    assert reach.widest_plane == 'yz' and reach.radii['yz'] > 0.005
    for plane, (a, b) in PLANES.items():
        radius = reach.radii[plane]
        assert radius > 0.0, plane
        assert np.all(_inside(hull, _circle(reach.center, 0.999 * radius, plane))), plane
        # so inside the hull of the samples projected onto the plane as well
        flat = Delaunay(reach.points[:, [a, b]])
        assert np.all(_inside(flat, _circle(reach.center, 0.999 * radius, plane)[:, [a, b]]))
        assert not np.all(_inside(hull, _circle(reach.center, 1.05 * radius, plane))), plane


def test_the_centre_is_the_sample_with_the_largest_circle_in_the_widest_plane(tendon_reach):
    reach = tendon_reach
    hull = Delaunay(reach.points)
    top = float(np.max(reach.box_max - reach.box_min))
    assert np.any(np.all(reach.points == reach.center, axis=1)), 'the centre is a reached point'
    best = {plane: _largest_circle(hull, reach.points, plane, top) for plane in PLANES}
    # the brute force agrees with the reported radius about the centre and finds none larger
    index = int(np.flatnonzero(np.all(reach.points == reach.center, axis=1))[0])
    for plane in PLANES:
        assert best[plane][index] == pytest.approx(reach.radii[plane], rel=0.01), plane
    assert reach.radii['yz'] >= 0.99 * max(best[plane].max() for plane in PLANES)
    # and the radii about any point (here the scene's workspace centre) as well
    point = reach.points.mean(axis=0)
    around = reach.radii_around(point)
    for plane in PLANES:
        brute = _largest_circle(hull, point[None], plane, top)[0]
        assert around[plane] == pytest.approx(brute, rel=0.01, abs=1e-6), plane


def test_arc_rod_reach_follows_the_closed_form_arc(arc_rod):
    reach = sample_reachable_set(arc_rod, 40)
    length, arm, max_tension = ARC['length'], ARC['arm'], ARC['max_tension']
    stiffness = ARC['E'] * np.pi * ARC['radius'] ** 4 / 4.0
    area = np.pi * ARC['radius'] ** 2

    def arc(tension):
        """Tip (axial, lateral) [m] of the rod bent by one tendon: a shortened circular arc."""
        curvature = tension * arm / stiffness
        angle = curvature * length * (1.0 - tension / (ARC['E'] * area))
        return np.sin(angle) / curvature, (1.0 - np.cos(angle)) / curvature

    for actuation, point in zip(reach.actuations, reach.points):
        on = np.flatnonzero(actuation)
        if len(on) == 1:
            axial, lateral = arc(actuation[on[0]])
            angle = np.deg2rad([0.0, 90.0, 180.0, 270.0][on[0]])
            expected = [axial, lateral * np.cos(angle), lateral * np.sin(angle)]
            np.testing.assert_allclose(point, expected, atol=1e-4)
        elif len(on) == 0:
            np.testing.assert_allclose(point, [length, 0.0, 0.0], atol=1e-9)
    # tendons only pull: the tip never moves beyond the rod's length; one tendon bends it the most
    # along its side, two neighbours (a moment sqrt(2) larger) the most in between
    _, side = arc(max_tension)
    assert reach.box_max[0] <= length + 1e-9
    assert np.all(np.abs(reach.points[:, 1:]) <= side + 1e-4)
    np.testing.assert_allclose(reach.box_max[1:], side, atol=1e-4)
    _, diagonal = arc(np.sqrt(2.0) * max_tension)
    assert np.all(np.hypot(reach.points[:, 1], reach.points[:, 2]) <= diagonal + 1e-4)
    # symmetric robot, no gravity: the centre is on the axis
    np.testing.assert_allclose(reach.center[1:], 0.0, atol=1e-9)


def test_the_reported_circle_is_reached_by_the_inverse_solver(arc_rod):
    reach = sample_reachable_set(arc_rod, 40)
    radius = 0.8 * reach.radii['yz']
    for target in _circle(reach.center, radius, 'yz')[::45]:
        solver = arc_rod.make_inverse_solver()
        for _ in range(200):
            out = solver.step(target[None])
        tip = arc_rod.forward(out.actuation, strict=True).effector_positions[-1]
        assert np.linalg.norm(tip - target) < 5e-5, (target, tip)


def test_sampling_is_deterministic_and_its_arguments_are_checked(tendon, tendon_reach):
    again = sample_reachable_set(tendon, SAMPLES, effector='tip')
    np.testing.assert_array_equal(again.points, tendon_reach.points)
    np.testing.assert_array_equal(again.center, tendon_reach.center)
    assert again.radii == tendon_reach.radii
    other = sample_reachable_set(tendon, SAMPLES, seed=1)
    assert not np.array_equal(other.points, tendon_reach.points)
    assert fewest_samples(8) == 36 and fewest_samples(1) == 10
    for kwargs, message in [({'samples': 9}, r'samples must be >= 36'),
                            ({'samples': 35}, r'samples must be >= 36'),
                            ({'samples': 40.0}, 'samples must be an integer'),
                            ({'samples': True}, 'samples must be an integer'),
                            ({'effector': 'elbow'}, "no effector 'elbow'"),
                            ({'effector': 1}, 'effector index 1 outside'),
                            ({'seed': -1}, 'seed must be a non-negative integer')]:
        with pytest.raises(ValueError, match=message):
            sample_reachable_set(tendon, **{'samples': SAMPLES, **kwargs})
    with pytest.raises(ValueError, match='3 finite coordinates'):
        tendon_reach.radii_around([0.0, np.nan, 0.0])


def test_a_flat_reach_has_circles_only_in_its_plane(tmp_path):
    text = '\n'.join(line for line in ARC_ROD.splitlines() if 'c90' not in line
                     and 'c270' not in line)
    reach = sample_reachable_set(load_scene(_scene_file(tmp_path, text)), 20)
    assert np.all(reach.points[:, 2] == pytest.approx(0.0, abs=1e-12))
    assert reach.flat_planes == ('yz', 'xz') and reach.widest_plane == 'xy'
    assert reach.radii['yz'] == reach.radii['xz'] == 0.0 < reach.radii['xy']
    flat = Delaunay(reach.points[:, :2])
    assert np.all(_inside(flat, _circle(reach.center, 0.999 * reach.radii['xy'], 'xy')[:, :2]))


def test_reachable_center_in_a_scene_file_is_the_sampled_centre(tmp_path, monkeypatch, tendon):
    calls = []
    real = reach_module.sample_reachable_set

    def counted(scene, samples):
        calls.append(samples)
        return real(scene, samples)

    monkeypatch.setattr(reach_module, 'sample_reachable_set', counted)
    scene = load_scene(_scene_file(tmp_path, _tendon_text(
        f'{{reachable_center: {{samples: {SAMPLES}}}}}')))
    assert calls == []  # lazy: nothing sampled at load
    center = scene.workspace_center
    assert calls == [SAMPLES]
    np.testing.assert_array_equal(center[-1], real(tendon, SAMPLES).center)
    np.testing.assert_array_equal(scene.workspace_center, center)
    assert calls == [SAMPLES]  # cached
    # the short form samples the default 300
    short = load_scene(_scene_file(tmp_path, _tendon_text('reachable_center'), 'short.yaml'))
    np.testing.assert_array_equal(short.workspace_center[-1], real(tendon).center)
    assert calls == [SAMPLES, 300]


@pytest.mark.parametrize('workspace, key, problem', [
    ('reachable_centre', 'workspace_center',
     "must be [x, y, z], {actuation_fraction: f} or reachable_center, got 'reachable_centre'"),
    ('{reachable_center: {samples: 20}}', 'workspace_center.reachable_center.samples',
     'must be >= 36, got 20'),
    ('{reachable_center: {sample: 50}}', 'workspace_center.reachable_center.sample',
     "unknown key, did you mean 'samples'?"),
    ('{reachable_center: 50}', 'workspace_center.reachable_center',
     'must be a mapping of keys, got int 50'),
    ('{actuation_fraction: 0.3, reachable_center: {}}', 'workspace_center',
     'give actuation_fraction or reachable_center, not both'),
])
def test_a_bad_reachable_center_names_the_file_and_the_key(tmp_path, workspace, key, problem):
    path = _scene_file(tmp_path, _tendon_text(workspace))
    with pytest.raises(ConfigError) as info:
        load_scene(path)
    assert (info.value.path, info.value.key, info.value.problem) == (str(path), key, problem)


def _millimetres(text):
    return np.array([float(v) for v in text.split(', ')]) * 1e-3


def test_cbha_scene_check_prints_the_reachable_set(capsys, tendon, tendon_reach):
    assert main(['check', 'tendon_6f_8c', '--ticks', '5', '--reach-samples', str(SAMPLES)]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    # the existing lines hold, the reachable set follows them
    assert 'workspace centre: [118.9, -0.0, -4.2] mm' in lines
    assert lines.index('workspace centre: [118.9, -0.0, -4.2] mm') < len(lines) - 5
    assert re.fullmatch(rf'reachable set of tip: {SAMPLES} samples, 0 not converged, '
                        r'\d+\.\d\d s', lines[-5]), out
    box = re.fullmatch(r'  box: \[(.*)\] mm to \[(.*)\] mm', lines[-4])
    np.testing.assert_allclose(_millimetres(box.group(1)), tendon_reach.box_min, atol=6e-5)
    np.testing.assert_allclose(_millimetres(box.group(2)), tendon_reach.box_max, atol=6e-5)
    center = re.fullmatch(r'  reachable centre: \[(.*)\] mm', lines[-3])
    np.testing.assert_allclose(_millimetres(center.group(1)), tendon_reach.center, atol=6e-5)
    circles = re.fullmatch(r'  largest circle around it: xy (\S+) mm, yz (\S+) mm, xz (\S+) mm '
                           r'\(.*\)', lines[-2])
    np.testing.assert_allclose([float(v) * 1e-3 for v in circles.groups()],
                               [tendon_reach.radii[p] for p in ('xy', 'yz', 'xz')], atol=6e-5)
    around = re.fullmatch(r'  around the workspace centre: xy (\S+) mm, yz (\S+) mm, '
                          r'xz (\S+) mm', lines[-1])
    expected = tendon_reach.radii_around(tendon.workspace_center[-1])
    np.testing.assert_allclose([float(v) * 1e-3 for v in around.groups()],
                               [expected[p] for p in ('xy', 'yz', 'xz')], atol=6e-5)


def test_cbha_scene_check_reach_samples_zero_skips_and_too_few_is_an_error(capsys):
    assert main(['check', 'tendon_6f_8c', '--ticks', '5', '--reach-samples', '0']) == 0
    out = capsys.readouterr().out
    assert out.splitlines()[-1].startswith('tick: ') and 'reachable' not in out
    with pytest.raises(SystemExit) as info:
        main(['check', 'tendon_6f_8c', '--ticks', '5', '--reach-samples', '12'])
    assert info.value.code == 2
    assert capsys.readouterr().err.splitlines()[-1] == (
        'cbha_scene: error: --reach-samples must be 0 (skip) or >= 36 for 8 actuators, got 12')
