"""dq_fk_ros.testing.assert_pose_close: poses in every accepted form, one line when apart."""

import math

from dq_fk_ros.testing import assert_pose_close, pose_difference
from geometry_msgs.msg import Pose, PoseStamped, TransformStamped
import pytest

HALF = math.sqrt(0.5)


def stamped(parent, child, xyz, q):
    t = TransformStamped()
    t.header.frame_id, t.child_frame_id = parent, child
    tr, r = t.transform.translation, t.transform.rotation
    (tr.x, tr.y, tr.z), (r.x, r.y, r.z, r.w) = xyz, q
    return t


def test_equal_poses_in_every_form_pass_and_q_and_minus_q_are_one_rotation():
    xyz, q = (1.025, 0.0, 1.445), (HALF, 0.0, HALF, 0.0)
    pose = Pose()
    (pose.position.x, pose.position.y, pose.position.z) = xyz
    o = pose.orientation
    o.x, o.y, o.z, o.w = q
    posed = PoseStamped()
    posed.header.frame_id, posed.pose = 'world', pose
    for actual in (stamped('world', 'eeCarry_seg6', xyz, q), stamped('world', 'e', xyz, q)
                   .transform, pose, posed, (xyz, q)):
        assert_pose_close(actual, (xyz, tuple(-v for v in q)))
    assert pose_difference((xyz, q), (xyz, q)) == (0.0, 0.0)


def test_a_pose_apart_names_its_frames_and_each_difference():
    actual = stamped('world', 'eeCarry_seg6', (1.0, 0.0, 1.445), (0.0, 0.0, 0.0, 1.0))
    expected = ((1.025, 0.0, 1.445), (0.0, 0.0, math.sin(0.05), math.cos(0.05)))
    with pytest.raises(AssertionError) as caught:
        assert_pose_close(actual, expected, atol_m=1e-3, atol_rad=1e-3)
    text = str(caught.value)
    assert text.startswith('pose of eeCarry_seg6 in world: position off by 25 mm (atol 1 mm); '
                           'orientation off by 5.73 deg (atol 0.0573 deg)')
    assert '\n' not in text
    # within the tolerance of one part, off in the other: only that one is said
    with pytest.raises(AssertionError, match=r'^pose of eeCarry_seg6 in world: orientation'):
        assert_pose_close(actual, expected, atol_m=0.03, atol_rad=1e-3)
    assert_pose_close(actual, expected, atol_m=0.03, atol_rad=0.11)


def test_nan_is_never_close_and_other_values_are_refused_in_one_line():
    with pytest.raises(AssertionError, match='position off by nan'):
        assert_pose_close(((math.nan, 0, 0), (0, 0, 0, 1)), ((0, 0, 0), (0, 0, 0, 1)))
    with pytest.raises(AssertionError, match='orientation off by nan'):
        assert_pose_close(((0, 0, 0), (0, 0, 0, 0)), ((0, 0, 0), (0, 0, 0, 1)))
    with pytest.raises(TypeError, match='^expected: a TransformStamped'):
        assert_pose_close(((0, 0, 0), (0, 0, 0, 1)), 'base_link')
