"""
The scene ``rao2021_tdcr`` against the reference model of Rao et al. 2021 (their benchmark robot).

The reference (:mod:`cbha_inverse.report.subsegment_cosserat`, a Cosserat rod between every two
disks, multiple shooting) is first checked against closed forms: the cantilever elastica under a
tip force and the constant curvature of a slightly pulled tendon. Then every benchmark case:
the scene's tip within 0.1 % of the robot's length (0.4 mm) of the paper's reference. The two
models differ in the force of a tendon on a disk it passes through (the paper keeps its
component in the disk's plane only, the package's cables that of a frictionless point contact:
0.36 mm apart at most in these cases) and in the discretisation (8 Timoshenko beams between
disks: 0.25 mm from their limit at most); the limit, extrapolated from 8 and 16 beams, is the
reference with point contact to a micrometre. docs/benchmark-rao2021.md.
"""

from cbha_inverse.config_files import read_yaml
from cbha_inverse.paths import config_path
from cbha_inverse.report import benchmark_rao2021 as bench
from cbha_inverse.report.references import elastica_tip
from cbha_inverse.report.subsegment_cosserat import solve_rod, TendonRobot
from cbha_inverse.scene import load_scene
import numpy as np
import pytest
import yaml

SCENE_PATH = config_path('scenes', 'rao2021_tdcr.yaml')
LENGTH = 0.4
E_MOD, NU, RADIUS = 54e9, 0.3, 0.7e-3
BENDING = E_MOD * np.pi * RADIUS ** 4 / 4.0          # EI [N m^2]


@pytest.fixture(scope='module')
def rows():
    """Return the benchmark's rows: every case, the scene and both references."""
    return bench.benchmark()[0]


def _rod(tendon_end=20):
    """Return the paper's backbone with one tendon at 10 mm along the paper's +x."""
    return TendonRobot((0.02,) * 20, E_MOD, NU, RADIUS, 0.0, ((0.01, 0.0, 0.0),), (tendon_end,))


@pytest.mark.parametrize('alpha', [0.5, 5.0])
def test_the_reference_rod_is_the_elastica_under_a_tip_force(alpha):
    """
    A transverse dead force ``alpha EI / L^2`` at the tip: the inextensible elastica's tip.

    The rod also shears and stretches: strains of ``P / GA``, about 1e-5 here.
    """
    force = alpha * BENDING / LENGTH ** 2
    tip = solve_rod(_rod(), [0.0], [force, 0.0, 0.0, 0.0, 0.0, 0.0]).tip
    along, across = elastica_tip(alpha)
    np.testing.assert_allclose(tip / LENGTH, [across, 0.0, along], atol=1e-5)


@pytest.mark.parametrize('pass_through', ['disk_plane', 'eyelet'])
def test_a_slightly_pulled_tendon_bends_the_reference_to_constant_curvature(pass_through):
    """A tendon at r to the tip pulled by tau: the arc of curvature ``tau r / EI`` toward it."""
    tension = 0.01
    curvature = tension * 0.01 / BENDING
    arc = np.array([(1.0 - np.cos(curvature * LENGTH)) / curvature, 0.0,
                    np.sin(curvature * LENGTH) / curvature])
    tip = solve_rod(_rod(), [tension], pass_through=pass_through).tip
    assert np.linalg.norm(tip - arc) < 1e-3 * arc[0], (tip, arc)


def test_the_reference_rejects_wrong_inputs():
    rod = _rod()
    with pytest.raises(ValueError, match='tensions'):
        solve_rod(rod, [1.0, 2.0])
    with pytest.raises(ValueError, match='tip_wrench'):
        solve_rod(rod, [1.0], [0.0, 0.0, np.nan, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match='pass_through'):
        solve_rod(rod, [1.0], pass_through='friction')
    with pytest.raises(ValueError, match='end_disks'):
        _rod(tendon_end=21)


def test_the_reference_steps_its_load_where_newton_fails_on_the_full_one():
    """5 N on a tip tendon turns the tip by 114 degrees: Newton from the straight rod fails."""
    robot = bench.reference_robot(read_yaml(SCENE_PATH))
    case = bench.Case('curl', (0.0, 0.0, 0.0, 5.0, 0.0, 0.0), (0.0, 0.0, 0.0), '')
    with pytest.raises(RuntimeError, match='load factor 0 reached in 1 load steps'):
        solve_rod(robot, case.tensions, max_load_steps=1)
    reference = bench.reference_tip(robot, case)
    ours = bench.our_tip(load_scene(SCENE_PATH), case)
    assert np.linalg.norm(ours - reference) < 1e-3 * LENGTH, (ours, reference)


def test_the_scene_routes_the_references_tendons():
    """The scene's holes, rotated into the paper's axes, are the reference's; rest tip at L."""
    scene = load_scene(SCENE_PATH)
    robot = bench.reference_robot(read_yaml(SCENE_PATH))
    cables = [c for group in scene.actuators.groups for c in group.cables]
    assert [c.name for c in cables] == list(scene.actuator_names)
    for cable, hole, end in zip(cables, robot.holes, robot.end_disks):
        np.testing.assert_allclose(cable.offsets, np.tile(bench.SCENE_FROM_PAPER @ hole,
                                                          (end + 1, 1)), atol=1e-15)
        np.testing.assert_array_equal(cable.frames, np.arange(end + 1) * 8)
    np.testing.assert_allclose(scene.rest_effector_positions[-1], [LENGTH, 0.0, 0.0],
                               atol=1e-12)
    assert scene.gravity is None


def test_every_case_lies_within_a_thousandth_of_the_length_of_the_papers_reference(rows):
    """The paper's reference and the point-contact variant; the cases do bend the robot."""
    assert [row['case'].name for row in rows] == [case.name for case in bench.CASES]
    for row in rows:
        name = row['case'].name
        assert row['error'] < 1e-3 * LENGTH, (name, row['error'])
        assert row['error_eyelet'] < 0.3e-3, (name, row['error_eyelet'])
        assert np.linalg.norm(row['ours'] - [LENGTH, 0.0, 0.0]) > 0.02, name


def test_the_model_converges_to_the_reference_with_point_contact(rows, tmp_path):
    """
    Richardson from 8 and 16 beams between disks: the reference with point contact.

    To 2 micrometres; and more than 0.1 mm from the paper's reference in the cases where the
    two contact models differ most (by 0.14 to 0.36 mm).
    """
    spec = read_yaml(SCENE_PATH)
    spec['chain']['beams_per_interval'] *= 2
    finer = tmp_path / 'finer.yaml'
    finer.write_text(yaml.safe_dump(spec))
    scene = load_scene(finer)
    for row in rows:
        name = row['case'].name
        limit = (4.0 * bench.our_tip(scene, row['case']) - row['ours']) / 3.0
        assert np.linalg.norm(limit - row['reference_eyelet']) < 2e-6, name
        if name in ('planar_c', 'spatial_cpp', 'spatial_load'):
            assert np.linalg.norm(limit - row['reference']) > 1e-4, name


def test_the_report_prints_its_table(capsys):
    assert bench.main(['--cases', 'spatial_matlab']) == 0
    out = capsys.readouterr().out
    line = next(t for t in out.splitlines() if t.startswith('| spatial_matlab |'))
    error_mm = float(line.split('|')[6])
    assert 0.0 < error_mm < 0.4, line
    assert 'largest error' in out
