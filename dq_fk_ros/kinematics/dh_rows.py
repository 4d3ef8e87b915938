"""
A DH row's transform in closed form, one configuration in Python floats.

:func:`relative_tuples`: every row's dual quaternion, the operator of [Radavelli2014]
eq. (3) (standard; modified ``h_x(alpha, a) h_z(theta, d)``); :func:`row_poses`: every
row's transform read off as ``(x, y, z, qx, qy, qz, qw)`` directly, without the dual part
(what TF carries for a DH row; the kernel's ``row_pose`` in ``_kernel_model.c`` is its
compiled twin, test_kernel.py).
"""

from collections.abc import Sequence
import math

from dq_fk_ros.kinematics.chain_table import ChainTable
from dq_fk_ros.kinematics.dual_quaternion import Coeffs, Pose


def row_standard(ca: float, sa: float, a: float, theta: float, d: float) -> Coeffs:
    """Evaluate the standard DH operator in closed form, [Radavelli2014] eq. (3)."""
    ct = math.cos(0.5 * theta)
    st = math.sin(0.5 * theta)
    ha = 0.5 * a
    hd = 0.5 * d
    return (ca * ct, sa * ct, sa * st, ca * st,
            -ha * sa * ct - hd * ca * st, ha * ca * ct - hd * sa * st,
            ha * ca * st + hd * sa * ct, -ha * sa * st + hd * ca * ct)


def row_modified(ca: float, sa: float, a: float, theta: float, d: float) -> Coeffs:
    """Evaluate the modified DH operator, closed form ``h_x(alpha, a) h_z(theta, d)``."""
    ct = math.cos(0.5 * theta)
    st = math.sin(0.5 * theta)
    ha = 0.5 * a
    hd = 0.5 * d
    return (ca * ct, sa * ct, -sa * st, ca * st,
            -hd * ca * st - ha * sa * ct, -hd * sa * st + ha * ca * ct,
            -hd * sa * ct - ha * ca * st, hd * ca * ct - ha * sa * st)


def relative_tuples(table: ChainTable, q: Sequence[float]) -> list[Coeffs]:
    """Return every row's transform frame i-1 -> frame i as 8 coefficients, at ``q``."""
    row = row_modified if table.modified else row_standard
    out = []
    for ca, sa, a, theta, d, scale, ti, di in table.rows:
        if ti >= 0:
            theta = theta + scale * q[ti]
        if di >= 0:
            d = d + scale * q[di]
        out.append(row(ca, sa, a, theta, d))
    return out


def row_poses(table: ChainTable, q: Sequence[float]) -> list[Pose]:
    """
    Every row's transform frame i-1 -> frame i as ``(x, y, z, qx, qy, qz, qw)``, ``qw >= 0``.

    Read off the row's operator directly: standard ``Rz(theta) Tz(d) Tx(a) Rx(alpha)``
    turns by ``(cos t/2 + k sin t/2)(cos al/2 + i sin al/2)`` and moves by
    ``(a cos t, a sin t, d)``; modified ``Rx(alpha) Tx(a) Rz(theta) Tz(d)`` turns by
    ``(cos al/2 + i sin al/2)(cos t/2 + k sin t/2)`` and moves by ``(a, -d sin al,
    d cos al)``: the same transforms as [Radavelli2014] eq. (3), without the dual part.
    ``q``: the chain's joint values, a list of floats.
    """
    cos, sin = math.cos, math.sin
    out = []
    append = out.append
    standard = not table.modified
    for ca, sa, a, theta, d, scale, ti, di, s_alpha, c_alpha in table.pose_rows:
        if ti >= 0:
            theta = theta + scale * q[ti]
        if di >= 0:
            d = d + scale * q[di]
        half = 0.5 * theta
        ct, st = cos(half), sin(half)
        if standard:
            qx, qy, qz, qw = sa * ct, sa * st, ca * st, ca * ct
            x, y, z = a * (1.0 - 2.0 * st * st), 2.0 * a * st * ct, d
        else:
            qx, qy, qz, qw = sa * ct, -sa * st, ca * st, ca * ct
            x, y, z = a, -d * s_alpha, d * c_alpha
        if qw < 0.0:
            qx, qy, qz, qw = -qx, -qy, -qz, -qw
        append((x, y, z, qx, qy, qz, qw))
    return out
