"""
tf2_geometry_msgs: geometry_msgs' stamped types moved by a ``TransformStamped``.

The names and results of geometry2's ``tf2_geometry_msgs/tf2_geometry_msgs.py`` (Jazzy):
``do_transform_point``, ``_vector3``, ``_pose``, ``_pose_stamped``,
``_pose_with_covariance_stamped``, ``_polygon_stamped``, ``transform_covariance``; and, as
the C++ ``tf2_geometry_msgs.hpp`` has them, ``do_transform_wrench`` (``WrenchStamped``) and
``do_transform_twist`` (``TwistStamped``). Each stamped result takes the transform's header
(its target frame and stamp), as geometry2's; each is registered for ``Buffer.transform``.

Differences from geometry2's Python, each on purpose: the transform given is never modified
(geometry2's ``do_transform_vector3`` zeroes its translation); a result quaternion is the
Hamilton product, normalised, with w >= 0 (geometry2's goes through a 4x4 matrix and an
eigen-decomposition and also gives w >= 0); the twist of the C++ ``VelocityStamped`` adds
the input to its own result, here it is the rigid-body map (below).

Poses are (x, y, z, qx, qy, qz, qw) tuples inside (:mod:`dq_fk_ros.transforms.pose_math`).
"""

import math

from dq_fk_ros.ros.tf_registration import ConvertRegistration, TransformRegistration
from dq_fk_ros.transforms.pose_math import _rotate, compose
from geometry_msgs.msg import (Point32, PointStamped, PolygonStamped, Pose, PoseStamped,
                               PoseWithCovarianceStamped, TwistStamped, Vector3Stamped,
                               WrenchStamped)
import numpy as np
from std_msgs.msg import Header


def transform_pose(transform) -> tuple:
    """Return a ``TransformStamped``'s pose (x y z qx qy qz qw), its quaternion normalised."""
    t, r = transform.transform.translation, transform.transform.rotation
    norm = math.sqrt(r.x * r.x + r.y * r.y + r.z * r.z + r.w * r.w)
    if not norm > 2.220446049250313e-16:   # as geometry2: no rotation (also NaN)
        return (t.x, t.y, t.z, 0.0, 0.0, 0.0, 1.0)
    if norm == 1.0:
        return (t.x, t.y, t.z, r.x, r.y, r.z, r.w)
    return (t.x, t.y, t.z, r.x / norm, r.y / norm, r.z / norm, r.w / norm)


def _header(transform) -> Header:
    """Return a copy of the transform's header (its frame and stamp: the result's)."""
    h = transform.header
    out = Header(frame_id=h.frame_id)
    out.stamp.sec, out.stamp.nanosec = h.stamp.sec, h.stamp.nanosec
    return out


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _set_xyz(msg, v):
    msg.x, msg.y, msg.z = float(v[0]), float(v[1]), float(v[2])


def do_transform_point(point: PointStamped, transform) -> PointStamped:
    """Return ``point`` moved by ``transform`` (rotated, then translated)."""
    pose = transform_pose(transform)
    p = point.point
    moved = _rotate(pose[3:], (p.x, p.y, p.z))
    res = PointStamped(header=_header(transform))
    _set_xyz(res.point, (moved[0] + pose[0], moved[1] + pose[1], moved[2] + pose[2]))
    return res


def do_transform_vector3(vector3: Vector3Stamped, transform) -> Vector3Stamped:
    """Return ``vector3`` rotated by ``transform`` (a direction: no translation)."""
    pose = transform_pose(transform)
    v = vector3.vector
    res = Vector3Stamped(header=_header(transform))
    _set_xyz(res.vector, _rotate(pose[3:], (v.x, v.y, v.z)))
    return res


def do_transform_pose(pose: Pose, transform) -> Pose:
    """Return ``pose`` (a ``Pose``, no header) moved by ``transform``."""
    p, q = pose.position, pose.orientation
    norm = math.sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w)
    quaternion = (0.0, 0.0, 0.0, 1.0) if not norm > 2.220446049250313e-16 else (
        q.x / norm, q.y / norm, q.z / norm, q.w / norm) if norm != 1.0 else (q.x, q.y, q.z, q.w)
    x, y, z, qx, qy, qz, qw = compose(transform_pose(transform), (p.x, p.y, p.z) + quaternion)
    if qw < 0.0:   # w >= 0, as geometry2's
        qx, qy, qz, qw = -qx, -qy, -qz, -qw
    res = Pose()
    _set_xyz(res.position, (x, y, z))
    o = res.orientation
    o.x, o.y, o.z, o.w = float(qx), float(qy), float(qz), float(qw)
    return res


def do_transform_pose_stamped(pose: PoseStamped, transform) -> PoseStamped:
    """Return ``pose`` moved by ``transform``, in the transform's frame."""
    return PoseStamped(header=_header(transform), pose=do_transform_pose(pose.pose, transform))


def transform_covariance(cov_in, transform) -> np.ndarray:
    """
    Return a 6x6 pose covariance (36 values, row-major) rotated by ``transform``.

    Each 3x3 block ``C`` becomes ``R C R^T`` (geometry2's ``transform_covariance``; the
    translation does not enter), R of the quaternion normalised.
    """
    x, y, z, w = transform_pose(transform)[3:]
    r = np.array([[2 * (w * w + x * x) - 1, 2 * (x * y - w * z), 2 * (x * z + w * y)],
                  [2 * (x * y + w * z), 2 * (w * w + y * y) - 1, 2 * (y * z - w * x)],
                  [2 * (x * z - w * y), 2 * (y * z + w * x), 2 * (w * w + z * z) - 1]])
    cov = np.asarray(cov_in, dtype=np.float64).reshape(2, 3, 2, 3)
    out = np.einsum('ij,ajbk,lk->aibl', r, cov, r)
    return out.reshape(36)


def do_transform_pose_with_covariance_stamped(pose: PoseWithCovarianceStamped,
                                              transform) -> PoseWithCovarianceStamped:
    """Return ``pose`` and its covariance moved by ``transform``."""
    res = PoseWithCovarianceStamped(header=_header(transform))
    res.pose.pose = do_transform_pose(pose.pose.pose, transform)
    res.pose.covariance = transform_covariance(pose.pose.covariance, transform)
    return res


def do_transform_polygon_stamped(polygon: PolygonStamped, transform) -> PolygonStamped:
    """Return each point of ``polygon`` moved by ``transform`` (float32 ``Point32``)."""
    pose = transform_pose(transform)
    res = PolygonStamped(header=_header(transform))
    for p in polygon.polygon.points:
        moved = _rotate(pose[3:], (p.x, p.y, p.z))
        res.polygon.points.append(Point32(x=moved[0] + pose[0], y=moved[1] + pose[1],
                                          z=moved[2] + pose[2]))
    return res


def _screw_pair(transform, axis, moment):
    """
    Return ``(R axis, R moment + t x R axis)``: a wrench's or a twist's pair moved.

    ``axis`` is the force (a wrench) or the angular velocity (a twist); ``moment`` the torque
    or the linear velocity, taken about the source frame's origin, then about the target's.
    """
    pose = transform_pose(transform)
    moved = _rotate(pose[3:], (axis.x, axis.y, axis.z))
    turned = _rotate(pose[3:], (moment.x, moment.y, moment.z))
    extra = _cross(pose[:3], moved)
    return moved, (turned[0] + extra[0], turned[1] + extra[1], turned[2] + extra[2])


def do_transform_wrench(wrench: WrenchStamped, transform) -> WrenchStamped:
    """
    Return ``wrench`` in the transform's frame: force ``R f``, torque ``R tau + t x R f``.

    The C++ ``tf2_geometry_msgs`` rule (``doTransform(Wrench)``): the torque about the new
    frame's origin.
    """
    force, torque = _screw_pair(transform, wrench.wrench.force, wrench.wrench.torque)
    res = WrenchStamped(header=_header(transform))
    _set_xyz(res.wrench.force, force)
    _set_xyz(res.wrench.torque, torque)
    return res


def do_transform_twist(twist: TwistStamped, transform) -> TwistStamped:
    """
    Return a body's ``twist`` in the transform's frame: ``w' = R w``, ``v' = R v + t x w'``.

    The twist is the velocity of the point at the source frame's origin and the angular
    velocity, both in the source frame's axes; the result is the velocity of the point at the
    target frame's origin moving with the body, in the target's axes (the rigid-body map,
    the dual of :func:`do_transform_wrench`).
    """
    angular, linear = _screw_pair(transform, twist.twist.angular, twist.twist.linear)
    res = TwistStamped(header=_header(transform))
    _set_xyz(res.twist.angular, angular)
    _set_xyz(res.twist.linear, linear)
    return res


def to_msg_msg(msg) -> object:
    """Return ``msg`` (a message is its own message form; geometry2's)."""
    return msg


def from_msg_msg(msg) -> object:
    """Return ``msg`` (geometry2's)."""
    return msg


for _type, _do in ((PointStamped, do_transform_point), (Vector3Stamped, do_transform_vector3),
                   (PoseStamped, do_transform_pose_stamped),
                   (PoseWithCovarianceStamped, do_transform_pose_with_covariance_stamped),
                   (PolygonStamped, do_transform_polygon_stamped),
                   (WrenchStamped, do_transform_wrench), (TwistStamped, do_transform_twist)):
    TransformRegistration().add_default(_type, _do)
for _type in (Vector3Stamped, PoseStamped, PointStamped):
    ConvertRegistration().add_to_msg(_type, to_msg_msg)
    ConvertRegistration().add_from_msg(_type, from_msg_msg)

__all__ = ['do_transform_point', 'do_transform_polygon_stamped', 'do_transform_pose',
           'do_transform_pose_stamped', 'do_transform_pose_with_covariance_stamped',
           'do_transform_twist', 'do_transform_vector3', 'do_transform_wrench',
           'from_msg_msg', 'to_msg_msg', 'transform_covariance', 'transform_pose']
