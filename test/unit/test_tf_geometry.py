"""
tf2_geometry_msgs (dq_fk_ros.ros.tf_geometry) against 4x4 matrices made with scipy.

Every expected value is computed here from the transform's definition (a rotation matrix of
scipy's and a translation), never with the package's pose arithmetic; geometry2's own test
(test_tf2_geometry_msgs.py) is run against the compat path by scripts/geometry2_tests.py.
"""

import copy

from dq_fk_ros.ros import tf_geometry
from geometry_msgs.msg import (Point32, PointStamped, PolygonStamped, Pose, PoseStamped,
                               PoseWithCovarianceStamped, Quaternion, TransformStamped,
                               TwistStamped, Vector3Stamped, WrenchStamped)
from hypothesis import given, strategies as st
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

unit = st.floats(-1.0, 1.0, allow_nan=False)
length = st.floats(-5.0, 5.0, allow_nan=False)
quaternions = st.tuples(unit, unit, unit, unit).filter(lambda q: sum(v * v for v in q) > 0.1)
vectors = st.tuples(length, length, length)


def make_transform(q, t, frame='base', stamp=(7, 250)):
    """Return a TransformStamped of quaternion ``q`` (x y z w, any norm) and translation t."""
    msg = TransformStamped()
    msg.header.frame_id, msg.child_frame_id = frame, 'camera'
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
    r, p = msg.transform.rotation, msg.transform.translation
    r.x, r.y, r.z, r.w = (float(v) for v in q)
    p.x, p.y, p.z = (float(v) for v in t)
    return msg


def matrix(q, t):
    """Return the 4x4 of rotation ``q`` (x y z w, normalised by scipy) and translation t."""
    m = np.eye(4)
    m[:3, :3] = Rotation.from_quat(q).as_matrix()
    m[:3, 3] = t
    return m


def xyz(msg):
    return np.array([msg.x, msg.y, msg.z])


@given(quaternions, vectors, vectors)
def test_a_point_is_rotated_then_translated(q, t, p):
    point = PointStamped()
    point.header.frame_id = 'camera'
    point.point.x, point.point.y, point.point.z = p
    out = tf_geometry.do_transform_point(point, make_transform(q, t))
    expected = matrix(q, t) @ np.array(p + (1.0,))
    np.testing.assert_allclose(xyz(out.point), expected[:3], atol=1e-9)
    assert out.header.frame_id == 'base'
    assert (out.header.stamp.sec, out.header.stamp.nanosec) == (7, 250)


@given(quaternions, vectors, vectors)
def test_a_vector_is_rotated_only_and_the_transform_is_left_as_it_was(q, t, v):
    vector = Vector3Stamped()
    vector.vector.x, vector.vector.y, vector.vector.z = v
    transform = make_transform(q, t)
    before = copy.deepcopy(transform)
    out = tf_geometry.do_transform_vector3(vector, transform)
    np.testing.assert_allclose(xyz(out.vector), Rotation.from_quat(q).apply(v), atol=1e-9)
    assert transform == before   # geometry2's zeroes its translation


@given(quaternions, vectors, quaternions, vectors)
def test_a_pose_is_the_product_of_the_matrices_with_w_not_negative(q, t, pq, pt):
    pose = PoseStamped()
    pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = pt
    o = pose.pose.orientation
    o.x, o.y, o.z, o.w = pq
    out = tf_geometry.do_transform_pose_stamped(pose, make_transform(q, t))
    expected = matrix(q, t) @ matrix(pq, pt)
    np.testing.assert_allclose(xyz(out.pose.position), expected[:3, 3], atol=1e-9)
    r = out.pose.orientation
    assert r.w >= 0.0
    assert abs(r.x ** 2 + r.y ** 2 + r.z ** 2 + r.w ** 2 - 1.0) < 1e-12
    np.testing.assert_allclose(Rotation.from_quat([r.x, r.y, r.z, r.w]).as_matrix(),
                               expected[:3, :3], atol=1e-9)
    assert out.header.frame_id == 'base'


def test_a_zero_quaternion_is_no_rotation_as_geometry2s():
    pose = Pose()
    pose.position.x = 1.0
    pose.orientation = Quaternion(x=0.0, y=0.0, z=0.0, w=0.0)
    out = tf_geometry.do_transform_pose(pose, make_transform((0, 0, 0, 0), (0, 2, 0)))
    assert (out.position.x, out.position.y, out.position.z) == (1.0, 2.0, 0.0)
    assert (out.orientation.x, out.orientation.w) == (0.0, 1.0)


@given(quaternions, vectors, st.lists(st.floats(-9, 9, allow_nan=False), min_size=36,
                                      max_size=36))
def test_a_covariance_is_rotated_block_by_block(q, t, values):
    pose = PoseWithCovarianceStamped()
    pose.pose.covariance = np.array(values)
    transform = make_transform(q, t)
    out = tf_geometry.do_transform_pose_with_covariance_stamped(pose, transform)
    r = Rotation.from_quat(q).as_matrix()
    big = np.zeros((6, 6))
    big[:3, :3] = big[3:, 3:] = r
    expected = big @ np.array(values).reshape(6, 6) @ big.T
    np.testing.assert_allclose(np.array(out.pose.covariance).reshape(6, 6), expected,
                               atol=1e-9 * (1 + np.abs(values).max()))


def test_geometry2s_covariance_example_is_exact():
    """The 180 degree turn about x of geometry2's test: signs flip, values exact."""
    row = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    pose = PoseWithCovarianceStamped()
    pose.pose.covariance = row * 6
    out = tf_geometry.transform_covariance(pose.pose.covariance,
                                           make_transform((1, 0, 0, 0), (1, 2, 3)))
    signs = np.array([1, -1, -1, 1, -1, -1])
    assert np.array_equal(out, (np.outer(signs, signs) * np.array(row * 6).reshape(6, 6))
                          .reshape(36))


def test_a_polygons_points_are_each_moved():
    polygon = PolygonStamped()
    polygon.polygon.points = [Point32(x=1.0, y=0.0, z=0.0), Point32(x=0.0, y=2.0, z=-1.0)]
    q, t = (0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4)), (1.0, 1.0, 1.0)   # 90 deg about z
    out = tf_geometry.do_transform_polygon_stamped(polygon, make_transform(q, t))
    got = [xyz(p) for p in out.polygon.points]
    np.testing.assert_allclose(got, [(1.0, 2.0, 1.0), (-1.0, 1.0, 0.0)], atol=1e-6)


@given(quaternions, vectors, vectors, vectors)
def test_a_wrench_moved_gives_the_same_torque_about_every_point(q, t, f, tau):
    """Force R f; torque about the new origin: R tau + t x (R f) (rigid-body statics)."""
    wrench = WrenchStamped()
    w = wrench.wrench
    w.force.x, w.force.y, w.force.z = f
    w.torque.x, w.torque.y, w.torque.z = tau
    out = tf_geometry.do_transform_wrench(wrench, make_transform(q, t))
    r = Rotation.from_quat(q)
    force = r.apply(f)
    np.testing.assert_allclose(xyz(out.wrench.force), force, atol=1e-9)
    # the torque about any point p of the target frame is the same from either side
    p = np.array([0.3, -1.2, 2.0])
    torque_source = r.apply(tau) + np.cross(np.asarray(t) - p, force)
    torque_target = xyz(out.wrench.torque) + np.cross(-p, force)
    np.testing.assert_allclose(torque_target, torque_source, atol=1e-8)


@given(quaternions, vectors, vectors, vectors)
def test_a_twist_moved_is_the_velocity_of_the_point_at_the_target_origin(q, t, v, w):
    """A body moving with (v, w) at the source origin: its point at the target origin."""
    twist = TwistStamped()
    twist.twist.linear.x, twist.twist.linear.y, twist.twist.linear.z = v
    twist.twist.angular.x, twist.twist.angular.y, twist.twist.angular.z = w
    out = tf_geometry.do_transform_twist(twist, make_transform(q, t))
    r = Rotation.from_quat(q)
    angular = r.apply(w)
    # the body point at the target's origin sits at -t from the source origin (target axes)
    expected = r.apply(v) + np.cross(angular, -np.asarray(t))
    np.testing.assert_allclose(xyz(out.twist.angular), angular, atol=1e-9)
    np.testing.assert_allclose(xyz(out.twist.linear), expected, atol=1e-8)


@pytest.mark.parametrize('kind', [PointStamped, Vector3Stamped, PoseStamped,
                                  PoseWithCovarianceStamped, PolygonStamped, WrenchStamped,
                                  TwistStamped])
def test_each_type_is_registered_for_buffer_transform(kind):
    from dq_fk_ros.ros.tf_registration import TransformRegistration
    assert TransformRegistration().get(kind).__module__ == 'dq_fk_ros.ros.tf_geometry'
