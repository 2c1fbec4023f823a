"""The frame tree: points between frames against direct homogeneous transforms; refusals named."""

from cbha_inverse.core.so3 import matrix_from_quat
from cbha_inverse.robot.frames import FrameTree
import numpy as np
import pytest


def _homogeneous(translation, quaternion):
    matrix = np.eye(4)
    matrix[:3, :3] = matrix_from_quat(quaternion)
    matrix[:3, 3] = translation
    return matrix


def test_points_cross_the_tree_as_the_product_of_its_transforms():
    """Cross base <- table <- mount and base <- camera, any pair, against 4x4 matrix products."""
    rng = np.random.default_rng(2)
    links = {'table': ('cbha_base', rng.normal(size=3), rng.normal(size=4)),
             'mount': ('table', rng.normal(size=3), rng.normal(size=4)),
             'camera': ('cbha_base', rng.normal(size=3), rng.normal(size=4))}
    tree = FrameTree()
    for child, (parent, t, q) in links.items():
        tree.set_transform(parent, child, t, q)

    def in_base(frame):
        matrix = np.eye(4)
        while frame != 'cbha_base':
            parent, t, q = links[frame]
            matrix = _homogeneous(t, q) @ matrix
            frame = parent
        return matrix

    point = rng.normal(size=3)
    for source in ('cbha_base', 'table', 'mount', 'camera'):
        for target in ('cbha_base', 'table', 'mount', 'camera'):
            expected = np.linalg.solve(in_base(target), in_base(source) @ [*point, 1.0])[:3]
            np.testing.assert_allclose(tree.transform_point(point, source, target), expected,
                                       atol=1e-12)
    assert tree.frames == ['camera', 'cbha_base', 'mount', 'table']


def test_a_new_transform_replaces_the_old_one():
    tree = FrameTree()
    tree.set_transform('cbha_base', 'table', [0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 1.0])
    tree.set_transform('cbha_base', 'table', [0.0, 0.0, 2.0], [0.0, 0.0, 0.0, 2.0])   # normalised
    np.testing.assert_allclose(tree.transform_point([1.0, 0.0, 0.0], 'table', 'cbha_base'),
                               [1.0, 0.0, 2.0])


def test_unknown_frames_separate_trees_and_bad_transforms_are_refused_by_name():
    tree = FrameTree()
    with pytest.raises(LookupError, match="'table' is unknown to TF \\(frames: none yet\\)"):
        tree.transform_point([0.0, 0.0, 0.0], 'table', 'cbha_base')
    tree.set_transform('cbha_base', 'table', [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
    tree.set_transform('world', 'camera', [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
    with pytest.raises(LookupError, match="'camera' and 'cbha_base'.*'world' and 'cbha_base'"):
        tree.transform_point([0.0, 0.0, 0.0], 'camera', 'cbha_base')
    with pytest.raises(LookupError, match="'shelf' is unknown"):
        tree.transform_point([0.0, 0.0, 0.0], 'shelf', 'cbha_base')
    for parent, child, t, q, message in (
            ('cbha_base', 'x', [np.nan, 0, 0], [0, 0, 0, 1], 'finite'),
            ('cbha_base', 'x', [0, 0, 0], [0, 0, 0, 0], 'non-zero'),
            ('cbha_base', 'cbha_base', [0, 0, 0], [0, 0, 0, 1], 'two different'),
            ('table', 'cbha_base', [0, 0, 0], [0, 0, 0, 1], 'loop')):
        with pytest.raises(ValueError, match=message):
            tree.set_transform(parent, child, t, q)
    # a refused transform changes nothing
    np.testing.assert_allclose(tree.transform_point([1.0, 2.0, 3.0], 'table', 'cbha_base'),
                               [1.0, 2.0, 3.0])
