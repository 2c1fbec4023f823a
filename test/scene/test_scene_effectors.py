"""
A scene's ``effectors:`` block with kinds (``docs/effectors.md``): what it builds, what it refuses.

Every mistake is one ``ConfigError`` naming the file and the key; the shipped ``cbha_approach``
scene builds the CBHA tip as an ``axis`` effector; ``cbha_scene check`` prints its tilt.
"""

import io

from cbha_inverse.errors import ConfigError
from cbha_inverse.paths import config_path
from cbha_inverse.scene import load_scene
from cbha_inverse.scene.cli import check
import numpy as np
import pytest


def _with_effectors(tmp_path, *lines):
    """Write the tendon_6f_8c scene with ``lines`` as its effectors block; return its path."""
    text = config_path('scenes', 'tendon_6f_8c.yaml').read_text()
    kept = [line for line in text.splitlines()
            if not line.startswith('effectors:') and '{name: tip, vertebra: 3' not in line]
    path = tmp_path / 'scene.yaml'
    path.write_text('\n'.join(kept + ['effectors:', *[f'  - {line}' for line in lines]]) + '\n')
    return path


def test_kinds_axes_and_weights_are_built(tmp_path):
    path = _with_effectors(
        tmp_path, '{name: mid, vertebra: 2}',
        '{name: tip, kind: axis, vertebra: 3, axis: [0.0, 2.0, 0.0], weights: {position: 0.5, '
        'orientation: [1.0, 2.0], orientation_length: 0.2}}',
        '{name: hand, kind: pose, frame: tip, offset: [0.01, 0.0, 0.0]}')
    effectors = load_scene(path).effectors
    assert effectors.kinds == ('point', 'axis', 'pose')
    np.testing.assert_allclose(effectors.axes[1], [0.0, 1.0, 0.0])
    np.testing.assert_allclose(effectors.row_weights,
                               [1, 1, 1, 0.5, 0.5, 0.5, 1, 1, 1, 0.2, 0.4, 0.1, 0.1, 0.1])
    np.testing.assert_array_equal(effectors.orientation_effectors, [1, 1, 2, 2, 2])


@pytest.mark.parametrize('line, key', [
    ('{name: tip, vertebra: 3, kind: spin}', 'kind'),
    ('{name: tip, vertebra: 3, axes: [1.0, 0.0, 0.0]}', 'axes'),
    ('{name: tip, vertebra: 3, axis: [1.0, 0.0, 0.0]}', 'axis'),
    ('{name: tip, vertebra: 3, kind: axis, axis: [0.0, 0.0, 0.0]}', 'axis'),
    ('{name: tip, vertebra: 3, kind: axis, axis: [1.0, 0.0]}', 'axis'),
    ('{name: tip, vertebra: 3, weights: {orientation: 1.0}}', 'orientation'),
    ('{name: tip, vertebra: 3, kind: pose, weights: {orientation: [1.0, 1.0]}}', 'orientation'),
    ('{name: tip, vertebra: 3, kind: pose, weights: {orientation_length: 0.0}}',
     'orientation_length'),
    ('{name: tip, vertebra: 3, weights: {position: -1.0}}', 'position'),
    ('{name: tip, vertebra: 3, weights: {turn: 1.0}}', 'turn')])
def test_a_bad_effector_is_one_error_naming_its_key(tmp_path, line, key):
    with pytest.raises(ConfigError) as raised:
        load_scene(_with_effectors(tmp_path, line))
    message = str(raised.value)
    assert 'scene.yaml' in message and 'effectors[0]' in message and key in message, message


def test_the_approach_scene_checks_with_its_tilt():
    """``cbha_scene check cbha_approach``: each bellows' tip displacement and axis tilt."""
    out = io.StringIO()
    assert check('cbha_approach', 20, out, reach_samples=0) == 0
    lines = [line for line in out.getvalue().splitlines() if 'tip' in line and 'tilt' in line]
    assert len(lines) == 6, out.getvalue()
    tilts = [float(line.split('tilt ')[1].split(' deg')[0]) for line in lines]
    # each bellows alone bends the arm: its tip axis tilts by tens of degrees
    assert min(tilts) > 10.0
