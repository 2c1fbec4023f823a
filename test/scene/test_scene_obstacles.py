"""A scene's obstacles and collision spheres: loading, defaults, refusals, clearance."""

import io
import re

from cbha_inverse.errors import ConfigError
from cbha_inverse.paths import config_path
from cbha_inverse.scene import load_scene
from cbha_inverse.scene.cli import check
import numpy as np
import pytest

TENDON = config_path('scenes', 'tendon_6f_8c.yaml')


def _scene(tmp_path, extra, base=TENDON):
    """Write ``base`` with ``extra`` YAML appended; return its path."""
    path = tmp_path / 'scene.yaml'
    path.write_text(base.read_text() + extra)
    return path


def test_the_table_scene_loads_its_obstacles_and_spheres():
    scene = load_scene('cbha_table')
    table, post = scene.obstacles
    assert [(o.name, o.shape) for o in (table, post)] == [('table', 'plane'),
                                                          ('post', 'cylinder')]
    np.testing.assert_array_equal(table.position, [0.0, 0.0, -0.08])
    assert (post.radius, post.length) == (0.015, 0.3)
    np.testing.assert_array_equal(scene.collision.frames, np.arange(1, 17))
    np.testing.assert_array_equal(scene.collision.radii, 0.0245)


def test_the_post_scene_is_the_cbha_with_obstacles():
    """
    ``cbha_post`` (the demo's obstacle runs) is ``cbha`` but for its obstacles and spheres.

    The demo's run without rows gives the inverse ``cbha``: the same model, bit for bit, at an
    actuation, the same actuators and workspace centre. Its post blocks the square's lower edge:
    the tip's sphere on the edge's middle is inside it, on the vertical edges clear of it.
    """
    post, plain = load_scene('cbha_post'), load_scene('cbha')
    assert plain.obstacles == () and [o.name for o in post.obstacles] == ['table', 'post']
    assert post.actuator_names == plain.actuator_names
    np.testing.assert_array_equal(post.workspace_center, plain.workspace_center)
    actuation = [40e3, 10e3, 60e3, 20e3, 70e3, 5e3]
    a, b = post.forward(actuation), plain.forward(actuation)
    assert np.array_equal(a.positions, b.positions) and np.array_equal(a.rotations, b.rotations)
    centre, radius = post.workspace_center[-1], post.collision.radii[-1]
    column = post.obstacles[1]
    # the post's axis is 29.25 mm beyond the square's plane: sqrt(29.25² + y²) - 10 - 24.5 mm
    for y, gap in ((0.0, -5.25e-3), (0.04, np.hypot(29.25e-3, 0.04) - 34.5e-3)):
        at = centre + [0.0, y, -0.04]
        assert column.signed_distance(at[None]).distance[0] - radius == pytest.approx(
            gap, abs=1e-5)


def test_default_spheres_take_the_chains_own_radius(tmp_path):
    """A beam's outer radius at every frame, or at the vertebrae; a segment's cavities' extent."""
    tendon = load_scene(TENDON)
    assert tendon.obstacles == ()
    np.testing.assert_array_equal(tendon.collision.frames, np.arange(1, 7))
    np.testing.assert_array_equal(tendon.collision.radii, 0.006)
    vertebrae = load_scene(_scene(tmp_path, 'collision: {per: vertebra}\n'))
    np.testing.assert_array_equal(vertebrae.collision.frames, [2, 4, 6])
    declared = load_scene(_scene(tmp_path, 'collision: {radius: 0.015}\n'))
    np.testing.assert_array_equal(declared.collision.radii, 0.015)
    # the CBHA's cavities reach 14 + 8.5 + 1 mm from the backbone (tube pitch radius, mean
    # inner radius, corrugation amplitude: meshes/cbha_segment_geometry.yaml)
    np.testing.assert_allclose(load_scene('cbha').collision.radii, 0.0235, atol=2e-4)


def test_obstacle_poses_and_sizes_are_read(tmp_path):
    scene = load_scene(_scene(tmp_path, """obstacles:
  - {name: wall, type: plane, pose: {position: [0.2, 0, 0], rpy: [0, -1.5707963267948966, 0]}}
  - {name: crate, type: box, size: [0.1, 0.2, 0.3], pose: {position: [0.1, 0.1, -0.2]}}
  - {name: rail, type: capsule, radius: 0.01, length: 0.0}
"""))
    wall, crate, rail = scene.obstacles
    # pitch -90 deg turns the plane's +z onto -x: the free side faces the arm
    query = wall.signed_distance([[0.15, 0.0, 0.0]])
    np.testing.assert_allclose(query.normal[0], [-1.0, 0.0, 0.0], atol=1e-15)
    assert query.distance[0] == pytest.approx(0.05)
    np.testing.assert_array_equal(crate.size, [0.1, 0.2, 0.3])
    assert rail.signed_distance([[0.0, 0.0, 0.03]]).distance[0] == pytest.approx(0.02)


@pytest.mark.parametrize('extra, message', [
    ('obstacles:\n  - {name: a, type: sphere, raduis: 0.1}\n',
     r"obstacles\[0\]\.raduis: unknown key, did you mean 'radius'\?"),
    ('obstacles:\n  - {name: a, type: cone, radius: 0.1}\n', r'obstacles\[0\]\.type: must be '
     r'one of'),
    ('obstacles:\n  - {name: a, type: box, radius: 0.1, size: [1, 1, 1]}\n',
     r'obstacles\[0\]\.radius: a box takes no radius'),
    ('obstacles:\n  - {name: a, type: sphere}\n', r'obstacles\[0\]\.radius: missing'),
    ('obstacles:\n  - {name: a, type: sphere, radius: -0.1}\n',
     r'obstacles\[0\]\.radius: must be > 0'),
    ('obstacles:\n  - {name: a, type: box, size: [1, 0, 1]}\n',
     r'obstacles\[0\]\.size: edges must be > 0'),
    ('obstacles:\n  - {name: a, type: capsule, radius: 0.1, length: -1}\n',
     r'obstacles\[0\]\.length: must be >= 0'),
    ('obstacles:\n  - {name: a, type: box, size: [1, 1]}\n',
     r'obstacles\[0\]\.size: must be a list of 3'),
    ('obstacles:\n  - {name: a, type: plane, pose: {position: [0, 0], rpy: [0, 0, 0]}}\n',
     r'obstacles\[0\]\.pose\.position: must be a list of 3'),
    ('obstacles:\n  - {name: a, type: plane, pose: {postion: [0, 0, 0]}}\n',
     r"obstacles\[0\]\.pose\.postion: unknown key, did you mean 'position'\?"),
    ('obstacles:\n  - {name: a, type: plane}\n  - {name: a, type: plane}\n',
     r"obstacles: obstacle 'a' named twice"),
    ('collision: {radius: 0}\n', r'collision\.radius: must be > 0'),
    ('collision: {per: link}\n', r'collision\.per: must be one of'),
    ('collision: {radius: 0.01, spacing: 2}\n', r'collision\.spacing: unknown key'),
    ('obstacle: []\n', r"obstacle: unknown key, did you mean 'obstacles'\?"),
])
def test_bad_obstacle_blocks_are_refused_naming_the_key(tmp_path, extra, message):
    path = _scene(tmp_path, extra)
    with pytest.raises(ConfigError, match=rf'^{re.escape(str(path))}: {message}'):
        load_scene(path)


def test_scene_check_prints_the_clearance_at_rest():
    """The table's clearance: the lowest sphere's height above the table top, a closed form."""
    out = io.StringIO()
    assert check('cbha_table', 1, out, reach_samples=0, actuation_fraction=0.0) == 0
    text = out.getvalue()
    scene = load_scene('cbha_table')
    rest = scene.forward(np.zeros(6))
    expected = (rest.positions[1:, 2] + 0.08 - 0.0245).min()
    assert f'minimum clearance at rest: {1e3 * expected:.1f} mm (frame 16 to table)' in text
    assert 'collision: 16 spheres at frames 1..16, radius 24.5 mm' in text
    assert re.search(r'post: cylinder radius 15\.0 mm, length 300\.0 mm .*; clearance at rest '
                     r'\d+\.\d mm \(frame \d+\)', text)


def test_scene_check_says_when_the_rest_shape_penetrates(tmp_path):
    """A ball around the tendon trunk's tip at rest: a negative clearance, said in words."""
    path = _scene(tmp_path, """obstacles:
  - {name: ball, type: sphere, radius: 0.01, pose: {position: [0.12, 0.0, 0.0]}}
""")
    out = io.StringIO()
    assert check(str(path), 1, out, reach_samples=0, actuation_fraction=0.0) == 0
    tip = load_scene(path).forward(np.zeros(8)).positions[-1]
    expected = np.linalg.norm(tip - [0.12, 0.0, 0.0]) - 0.01 - 0.006
    assert (f'minimum clearance at rest: {1e3 * expected:.1f} mm (frame 6 to ball): the rest '
            'shape penetrates it') in out.getvalue()
