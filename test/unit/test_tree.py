"""A tree of transforms composed into poses in its root, against 4x4 matrices."""

import math

from dq_fk_ros.kinematics.tree import coeffs_from_pose, compose_tree, depths, roots
import homogeneous as hm
import numpy as np


def random_pose(rng):
    q = rng.normal(size=4)
    return tuple(rng.normal(size=3).tolist() + (q / np.linalg.norm(q)).tolist())


def test_composed_poses_equal_the_product_of_matrices():
    rng = np.random.default_rng(7)
    edges = {'a': ('world', random_pose(rng)), 'b': ('a', random_pose(rng)),
             'c': ('b', random_pose(rng)), 'd': ('a', random_pose(rng)),
             'other': ('elsewhere', random_pose(rng))}
    poses = compose_tree(edges, 'world')
    assert sorted(poses) == ['a', 'b', 'c', 'd']  # 'other' hangs under another root
    matrix = {'world': np.eye(4)}
    for name in ('a', 'b', 'c', 'd'):
        parent, pose = edges[name]
        matrix[name] = matrix[parent] @ hm.matrix_of_pose(pose[:3], pose[3:])
        np.testing.assert_allclose(hm.matrix_of_pose(poses[name][:3], poses[name][3:]),
                                   matrix[name], atol=1e-12)
        assert poses[name][6] >= 0.0  # canonical: w >= 0
    assert roots(edges) == ['elsewhere', 'world']
    assert depths(edges, 'world') == {'a': 1, 'b': 2, 'c': 3, 'd': 2}


def test_unnormalised_quaternions_are_normalised_and_bad_ones_dropped():
    edges = {'a': ('w', (1.0, 0.0, 0.0, 0.0, 0.0, 2.0, 2.0)),       # 90 deg about z, x 2
             'b': ('a', (1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)),       # zero quaternion
             'c': ('w', (math.nan, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))}  # NaN position
    poses = compose_tree(edges, 'w')
    assert sorted(poses) == ['a']
    np.testing.assert_allclose(poses['a'], [1, 0, 0, 0, 0, math.sqrt(0.5), math.sqrt(0.5)],
                               atol=1e-15)
    assert coeffs_from_pose((0, 0, 0, 0, 0, 0, 0)) is None


def test_a_cycle_ends_the_walk():
    pose = (0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    edges = {'a': ('root', pose), 'b': ('a', pose), 'a2': ('b', pose), 'root2': ('root', pose)}
    edges['root'] = ('b', pose)  # root's parent is below it: a cycle through the root
    poses = compose_tree(edges, 'root')
    assert sorted(poses) == ['a', 'a2', 'b', 'root2']
    assert poses['b'][0] == 0.2 or math.isclose(poses['b'][0], 0.2)
    assert roots(edges) == []


def test_every_component_of_an_unnormalised_quaternion_is_scaled():
    edges = {'a': ('w', (0.5, -1.0, 2.0, 1.0, 2.0, 2.0, 4.0))}  # norm 5
    pose = compose_tree(edges, 'w')['a']
    np.testing.assert_allclose(pose, [0.5, -1.0, 2.0, 0.2, 0.4, 0.4, 0.8], atol=1e-15)


def test_positions_whose_sum_overflows_are_refused_as_non_finite_ones_are():
    """A composed pose adds positions: 1e308 and 1e308 could not give a finite one."""
    for position in [(1e308, 0.0, 1e308), (1e308, 1e308, 0.0), (0.0, 1e308, 1e308),
                     (math.nan, 0.0, 0.0), (0.0, 0.0, -math.inf)]:
        assert coeffs_from_pose(position + (0.0, 0.0, 0.0, 1.0)) is None, position
    assert coeffs_from_pose((1e307, 1e307, 1e307, 0.0, 0.0, 0.0, 1.0)) is not None


def test_a_cycle_or_a_bad_pose_skips_that_child_not_its_siblings():
    good = (1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    bad = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)   # no rotation: refused
    edges = {'bad': ('root', bad), 'ok': ('root', good)}
    assert set(compose_tree(edges, 'root')) == {'ok'}
    cycle = {'a': ('root', good), 'root': ('a', good), 'b': ('a', good)}  # a's children: root, b
    assert set(compose_tree(cycle, 'root')) == {'a', 'b'}
    assert depths(cycle, 'root') == {'a': 1, 'b': 2}
