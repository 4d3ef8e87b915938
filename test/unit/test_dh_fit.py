"""The common-normal geometry under ``dq_fk from-urdf``, line by line against least squares."""

from dq_fk_ros.description.dh_fit import (common_normal, frames_on_axes, LENGTH_TOL_M,
                                          normal_feet, PARALLEL_TOL)
import numpy as np
import pytest


def unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def feet_by_least_squares(p1, u1, p2, u2):
    """Return ``(s, t)`` minimising ``|p1 + s u1 - p2 - t u2|`` (an independent oracle)."""
    (s, minus_t), *_ = np.linalg.lstsq(np.column_stack([u1, -u2]), p2 - p1, rcond=None)
    return s, minus_t


SKEW = [  # neither perpendicular nor through the origin: every term of the formula counts
    (np.array([1.0, 2.0, 3.0]), unit([0, 0.3, 1]), np.array([4.0, -5.0, 6.5]), unit([1, 1, 0.2])),
    (np.array([-0.2, 0.1, 0.0]), unit([1, 0, 0]), np.array([0.3, 0.7, -0.4]), unit([2, 1, 3])),
]


@pytest.mark.parametrize('p1, u1, p2, u2', SKEW)
def test_normal_feet_are_the_closest_points(p1, u1, p2, u2):
    np.testing.assert_allclose(normal_feet(p1, u1, p2, u2),
                               feet_by_least_squares(p1, u1, p2, u2), atol=1e-12)


@pytest.mark.parametrize('p1, u1, p2, u2', SKEW)
def test_the_common_normal_of_skew_lines_points_from_the_first_to_the_second(p1, u1, p2, u2):
    foot1, foot2, x, kind = common_normal(p1, u1, p2, u2, p1, np.array([1.0, 0, 0]))
    s, t = feet_by_least_squares(p1, u1, p2, u2)
    assert kind == 'skew'
    np.testing.assert_allclose(foot1, p1 + s * u1, atol=1e-12)
    np.testing.assert_allclose(foot2, p2 + t * u2, atol=1e-12)
    np.testing.assert_allclose(x, unit(foot2 - foot1), atol=1e-12)   # unit, first to second


def test_a_short_normal_still_points_from_the_first_line_to_the_second():
    z, y = np.array([0.0, 0, 1]), np.array([0.0, 1, 0])
    for gap in (0.5, -0.5):   # |gap| < 1: its direction, not its length, decides
        _, _, x, kind = common_normal(np.zeros(3), z, np.array([gap, 0, 2.0]), y, np.zeros(3),
                                      np.array([1.0, 0, 0]))
        assert kind == 'skew'
        np.testing.assert_allclose(x, [np.sign(gap), 0, 0], atol=1e-15)


def test_intersecting_lines_take_the_sign_nearer_the_previous_x():
    z, x_axis = np.array([0.0, 0, 1]), np.array([1.0, 0, 0])
    p2 = np.array([0.0, 0, 1.0])   # z through the origin meets x through (0, 0, 1)
    for before, want in (((0, -1.0, 0), (0, -1, 0)), ((0, 0.5, 0), (0, 1, 0)),
                         ((1.0, 0, 0), (0, 1, 0))):   # orthogonal: z x x as it is
        foot1, foot2, x, kind = common_normal(np.zeros(3), z, p2, x_axis, np.zeros(3),
                                              np.array(before))
        assert kind == 'intersecting'
        np.testing.assert_allclose(foot1, [0, 0, 1.0], atol=1e-15)
        np.testing.assert_allclose(foot2, [0, 0, 1.0], atol=1e-15)
        np.testing.assert_allclose(x, want, atol=1e-15)
    slanted = unit([1.0, 0, 1])   # not perpendicular: x is still a unit vector
    _, _, x, kind = common_normal(np.zeros(3), z, p2, slanted, np.zeros(3), np.array(before))
    assert kind == 'intersecting'
    np.testing.assert_allclose(x, [0, 1.0, 0], atol=1e-15)
    # lines LENGTH_TOL_M apart do not meet
    foot1, foot2, x, kind = common_normal(np.zeros(3), z, np.array([0, LENGTH_TOL_M, 5.0]),
                                          x_axis, np.zeros(3), np.array(before))
    assert np.linalg.norm(foot2 - foot1) == LENGTH_TOL_M and kind == 'skew'


def test_parallel_and_coincident_lines_and_their_thresholds():
    z, before, through = np.array([0.0, 0, 1]), np.array([0.0, 1, 0]), np.array([0, 0, 0.5])
    foot1, foot2, x, kind = common_normal(np.zeros(3), z, np.array([0.3, 0, 9.0]), z, through,
                                          before)
    assert kind == 'parallel'
    np.testing.assert_allclose(foot1, through, atol=1e-15)
    np.testing.assert_allclose(foot2, [0.3, 0, 0.5], atol=1e-15)
    np.testing.assert_allclose(x, [1.0, 0, 0], atol=1e-15)
    # two parallel lines LENGTH_TOL_M apart are parallel, not one line
    assert common_normal(np.zeros(3), z, np.array([0, LENGTH_TOL_M, 0]), z, np.zeros(3),
                         before)[3] == 'parallel'
    assert common_normal(np.zeros(3), z, np.array([0, 0.5 * LENGTH_TOL_M, 0]), z,
                         np.zeros(3), before)[3:] == ('coincident',)
    # axes PARALLEL_TOL apart (|u1 x u2| exactly that) are not parallel
    u1, u2 = np.array([1.0, 0, 0]), np.array([np.sqrt(1 - PARALLEL_TOL ** 2), PARALLEL_TOL, 0])
    assert np.linalg.norm(np.cross(u1, u2)) == PARALLEL_TOL
    assert common_normal(np.zeros(3), u1, np.array([0, 0, 1.0]), u2, np.zeros(3),
                         before)[3] == 'skew'
    assert normal_feet(np.zeros(3), u1, np.array([0, 0, 1.0]), u2) is not None
    assert normal_feet(np.zeros(3), u1, np.array([0, 0, 1.0]), u1) is None


def test_frame_0s_x_is_the_base_links_x_else_its_y():
    for u1, want in ((unit([0, 0.2, 1]), [1.0, 0, 0]),
                     (unit([1, 0, 9e-7]), [0, 1.0, 0]),   # x within 1e-6 rad of the axis
                     (unit([1, 7e-7, 0]), [0, 1.0, 0])):
        frames, kinds = frames_on_axes([(np.array([0.0, 0, 0.4]), u1)], 'standard')
        assert kinds == ['first']
        want = unit(np.array(want) - np.dot(want, u1) * u1)   # made normal to the axis
        np.testing.assert_allclose(frames[0][:3, 0], want, atol=1e-12)
        np.testing.assert_allclose(frames[0][:3, 2], u1, atol=1e-15)
