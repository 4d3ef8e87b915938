"""
A DH row compiled into its sparse factors, and the factor program run: the FK reference.

Each row becomes its z and x factors (:class:`ZStep`, :class:`XStep`, [Zivkovic2023] eqs.
(13)-(15)) once (:func:`row_program`); :func:`run_program` multiplies a base by them, on
floats or on numpy columns of configurations. It is the reference every fast path is held
to: the compiled kernel (test_kernel.py), the straight-line code of
:mod:`~dq_fk_ros.kinematics.dh_code` (test_dh.py, to the bit).

Dual quaternions are 8 coefficients ``(w, x, y, z, w', x', y', z')``; the real part is
``aw, ax, ay, az``, the dual part ``bw, bx, by, bz``.
"""

from collections.abc import Callable, Sequence
import math
from typing import NamedTuple

from dq_fk_ros.kinematics.dh_joint import DHJoint

# The sparse factorisation of a DH row ([Zivkovic2023] eqs. (13)-(15)): the z factor
# Rz(theta) Tz(d) = (c + s k)(1 + eps d/2 k) and the x factor Tx(a) Rx(alpha) =
# (1 + eps a/2 i)(c + s i) each touch a few coefficients only, so applying them costs a
# fraction of a full product with the row's eq. (3) operator.
Z, X = 0, 1   # the kinds of step


class ZStep(NamedTuple):
    """
    A row's z factor ``Rz(theta) Tz(d)``: theta = theta + scale q[ti], d = d + scale q[di].

    An index of -1 means constant; ``mark``: the row's frame is complete after this step.
    """

    kind: int          # Z
    theta: float
    scale: float
    ti: int
    d: float
    di: int
    mark: bool


class XStep(NamedTuple):
    """A row's x factor ``Tx(a) Rx(alpha)``, constant; ``mark`` as for :class:`ZStep`."""

    kind: int          # X
    half_a: float
    cos_half_alpha: float
    sin_half_alpha: float
    has_rotation: bool
    unused: int        # (the same length as ZStep: the loops unpack both alike)
    mark: bool


def row_program(joint: DHJoint, ti: int, di: int, modified: bool) -> list[ZStep | XStep]:
    """
    Compile one DH row into its z and x factors (:class:`ZStep`, :class:`XStep`).

    Standard: ``Rz(theta) Tz(d) Tx(a) Rx(alpha)``; modified: ``Rx(alpha) Tx(a) Rz(theta)
    Tz(d)``; the last factor marks the row's frame.
    """
    ops = [[Z, joint.theta, joint.scale, ti, joint.d, di, False]]
    if joint.a or joint.alpha:
        ops.append([X, 0.5 * joint.a, math.cos(0.5 * joint.alpha),
                    math.sin(0.5 * joint.alpha), bool(joint.alpha), 0, False])
        if modified:
            ops.reverse()
    ops[-1][-1] = True
    return [ZStep(*op) if op[0] == Z else XStep(*op) for op in ops]


def run_program(program: Sequence[ZStep | XStep], base: Sequence, q: Sequence,
                cos: Callable, sin: Callable) -> list[tuple]:
    """
    Multiply ``base`` by the compiled factors; return the frames marked along the way.

    Works on floats (``q`` a list, ``cos``/``sin`` from math) and on numpy arrays (``q`` a
    sequence of columns, one per joint variable, ``cos``/``sin`` from numpy) alike.
    The real part is ``(aw, ax, ay, az)``, the dual part ``(bw, bx, by, bz)``.
    """
    aw, ax, ay, az, bw, bx, by, bz = base
    frames = [base]
    for op, p1, p2, p3, p4, p5, mark in program:
        if op == Z:  # h (c + s k) (1 + eps hd k)
            half = 0.5 * p1 if p3 < 0 else 0.5 * (p1 + p2 * q[p3])
            c, s = cos(half), sin(half)
            aw, ax, ay, az, bw, bx, by, bz = (
                aw * c - az * s, ax * c + ay * s, ay * c - ax * s, az * c + aw * s,
                bw * c - bz * s, bx * c + by * s, by * c - bx * s, bz * c + bw * s)
            if p5 >= 0 or p4:
                hd = 0.5 * p4 if p5 < 0 else 0.5 * (p4 + p2 * q[p5])
                bw, bx, by, bz = bw - hd * az, bx + hd * ay, by - hd * ax, bz + hd * aw
        else:  # h (1 + eps ha i) (c + s i), constant
            if p1:
                bw, bx, by, bz = bw - p1 * ax, bx + p1 * aw, by + p1 * az, bz - p1 * ay
            if p4:
                aw, ax, ay, az, bw, bx, by, bz = (
                    aw * p2 - ax * p3, ax * p2 + aw * p3, ay * p2 + az * p3, az * p2 - ay * p3,
                    bw * p2 - bx * p3, bx * p2 + bw * p3, by * p2 + bz * p3, bz * p2 - by * p3)
        if mark:
            frames.append((aw, ax, ay, az, bw, bx, by, bz))
    return frames


__all__ = ['row_program', 'run_program', 'XStep', 'Z', 'X', 'ZStep']
