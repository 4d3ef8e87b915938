"""
Poses as tuples (x, y, z, qx, qy, qz, qw) for tf2's rules: composed, inverted, interpolated.

The operations are written out as tf2's LinearMath computes them (``quatRotate``, the
Hamilton product, ``Quaternion::slerp`` on the shortest arc) and in the order
``transforms/tf_math.h`` computes them in C, so that the C walk and this reference agree to
the last bit (``test_tf_buffer_core.py``). :func:`screw_interpolate` is the dual-quaternion
ScLERP of ``DualQuaternion.sclerp``, not tf2's.
"""

import math


def slerp(q0, q1, ratio) -> tuple:
    """Return the rotation ``ratio`` of the way from q0 to q1 (x y z w) as tf2's slerp does."""
    x0, y0, z0, w0 = q0
    x1, y1, z1, w1 = q1
    dot = x0 * x1 + y0 * y1 + z0 * z1 + w0 * w1
    norms = math.sqrt((x0 * x0 + y0 * y0 + z0 * z0 + w0 * w0) *
                      (x1 * x1 + y1 * y1 + z1 * z1 + w1 * w1))
    theta = math.acos(min(1.0, max(-1.0, abs(dot) / norms)))
    if theta == 0.0:
        return (x0, y0, z0, w0)
    d = 1.0 / math.sin(theta)
    s0 = math.sin((1.0 - ratio) * theta)
    s1 = math.sin(ratio * theta)
    if dot < 0:
        s1 = -s1
    return ((x0 * s0 + x1 * s1) * d, (y0 * s0 + y1 * s1) * d, (z0 * s0 + z1 * s1) * d,
            (w0 * s0 + w1 * s1) * d)


def screw_interpolate(a, b, ratio) -> tuple:
    """Return the pose ``ratio`` of the way from ``a`` to ``b`` along their screw (ScLERP)."""
    from dq_fk_ros.kinematics.dual_quaternion import DualQuaternion
    import numpy as np
    first = DualQuaternion.from_pose((a[6], a[3], a[4], a[5]), a[:3])
    second = DualQuaternion.from_pose((b[6], b[3], b[4], b[5]), b[:3])
    if float(np.dot(first.real, second.real)) < 0.0:
        second = -second   # the same pose: the shorter screw, as slerp's shortest arc
    pose = first.sclerp(second, ratio).to_pose_xyzw()
    return tuple(float(x) for x in pose)


def _rotate(q, v):
    """Return ``q * v * conj(q)`` (tf2's ``quatRotate``) for q = (x y z w), v = (x y z)."""
    qx, qy, qz, qw = q
    vx, vy, vz = v
    # t = 2 q_vec x v; v' = v + w t + q_vec x t (q normalised)
    tx = 2.0 * (qy * vz - qz * vy)
    ty = 2.0 * (qz * vx - qx * vz)
    tz = 2.0 * (qx * vy - qy * vx)
    return (vx + qw * tx + qy * tz - qz * ty, vy + qw * ty + qz * tx - qx * tz,
            vz + qw * tz + qx * ty - qy * tx)


def _multiply(a, b):
    """Return the Hamilton product ``a * b`` of quaternions (x y z w)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)


def compose(a, b) -> tuple:
    """Return the pose ``a * b`` (x y z qx qy qz qw): b expressed in a's parent."""
    p = _rotate(a[3:], b[:3])
    return (p[0] + a[0], p[1] + a[1], p[2] + a[2]) + _multiply(a[3:], b[3:])


def inverse(a) -> tuple:
    """Return the inverse of the pose ``a`` (x y z qx qy qz qw)."""
    q = (-a[3], -a[4], -a[5], a[6])
    p = _rotate(q, a[:3])
    return (-p[0], -p[1], -p[2]) + q


IDENTITY = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)


__all__ = ['compose', 'IDENTITY', 'inverse', 'screw_interpolate', 'slerp']
