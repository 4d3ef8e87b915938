"""
DH frames fitted on joint axes: the common-normal geometry of ``dq_fk from-urdf``.

Each moving joint at zero is a line (its axis through its origin); the DH frames are built
on those lines by their common normals ([Radavelli2014] Sec. 2, Spong's or Craig's rules)
and each row's ``(theta, d, a, alpha)`` read off two consecutive frames. numpy only.
"""

from collections.abc import Sequence
import math

import numpy as np

PARALLEL_TOL = 1e-9         # |sin| of the angle between two axes below which they are parallel
LENGTH_TOL_M = 1e-9         # distances below which two points (or lines) meet


def _unit(v):
    return v / np.linalg.norm(v)


def common_normal(p1: np.ndarray, u1: np.ndarray, p2: np.ndarray, u2: np.ndarray,
                  through: np.ndarray, x_before: np.ndarray) -> tuple:
    """
    Return ``(foot on line 1, foot on line 2, x, kind)`` of the common normal of two lines.

    Parallel lines: the normal through ``through`` (a point on line 1); coincident ones:
    ``x_before``; intersecting ones: ``+-(u1 x u2)``, the sign nearer ``x_before``.
    """
    cross = np.cross(u1, u2)
    sin = np.linalg.norm(cross)
    w = p1 - p2
    if sin < PARALLEL_TOL:
        foot2 = p2 + np.dot(through - p2, u2) * u2
        gap = foot2 - through
        if np.linalg.norm(gap) < LENGTH_TOL_M:
            return through, through, x_before, 'coincident'
        return through, foot2, _unit(gap), 'parallel'
    # the feet p1 + s u1, p2 + t u2, with 1 - (u1.u2)^2 = |u1 x u2|^2 and the numerators
    # as cross products: no cancellation for nearly parallel axes (Romeo's thumbs, 1e-7 rad)
    denominator = np.dot(cross, cross)
    s = -np.dot(np.cross(u2, cross), w) / denominator
    t = -np.dot(np.cross(u1, cross), w) / denominator
    foot1, foot2 = p1 + s * u1, p2 + t * u2
    gap = foot2 - foot1
    if np.linalg.norm(gap) < LENGTH_TOL_M:
        middle = 0.5 * (foot1 + foot2)
        x = cross / sin
        return middle, middle, (-x if np.dot(x, x_before) < 0.0 else x), 'intersecting'
    # the normal is along u1 x u2: exact, where the direction of a short gap is not
    x = cross / sin
    return foot1, foot2, (-x if np.dot(x, gap) < 0.0 else x), 'skew'


def frames_on_axes(lines: Sequence[tuple], convention: str) -> tuple[list, list]:
    """
    Return the DH frames 0..n as 4x4 matrices (base link coordinates) and each axis' case.

    ``lines``: ``(point, unit direction)`` of the n joint axes at zero.
    """
    n = len(lines)
    p1, u1 = lines[0]
    reference = p1 + np.dot(-p1, u1) * u1   # on axis 1, closest to the base link's origin
    # frame 0's x: the base link's x (else y) where the first axis allows, so that the base
    # transform is as plain as the URDF
    x = None
    for axis in (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])):
        projected = axis - np.dot(axis, u1) * u1
        if np.linalg.norm(projected) > 1e-6:
            x = _unit(projected)
            break
    x0 = x
    normals, kinds = [], ['first']
    through = reference
    for i in range(n - 1):
        (pa, ua), (pb, ub) = lines[i], lines[i + 1]
        foot1, foot2, x, kind = common_normal(pa, ua, pb, ub, through, x)
        normals.append((foot1, foot2, x))
        kinds.append(kind)
        through = foot2
    x_last = normals[-1][2] if normals else x0

    def frame(origin, x_axis, z_axis):
        m = np.eye(4)
        x_axis = _unit(x_axis - np.dot(x_axis, z_axis) * z_axis)
        m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x_axis, np.cross(z_axis, x_axis), z_axis, origin
        return m

    if convention == 'standard':  # frame i (0..n-1): z on axis i+1, x on the normal i/i+1
        frames = [frame(reference, x0, u1)]
        for i in range(1, n):
            frames.append(frame(normals[i - 1][1], normals[i - 1][2], lines[i][1]))
        frames.append(frames[-1].copy())
    else:  # modified: frame i (1..n): z on axis i, x on the normal i/i+1; frame 0 = frame 1
        frames = []
        for i in range(n - 1):
            frames.append(frame(normals[i][0], normals[i][2], lines[i][1]))
        last_origin = normals[-1][1] if normals else reference
        frames.append(frame(last_origin, x_last, lines[-1][1]))
        frames.insert(0, frames[0].copy())
    return frames, kinds


def _angle(a, b, about):
    return math.atan2(float(np.dot(np.cross(a, b), about)), float(np.dot(a, b)))


def dh_row(before: np.ndarray, after: np.ndarray, convention: str) -> tuple[float, ...]:
    """Return ``(theta, d, a, alpha)`` taking DH frame ``before`` to ``after`` (4x4 each)."""
    x0, z0, o0 = before[:3, 0], before[:3, 2], before[:3, 3]
    x1, z1, o1 = after[:3, 0], after[:3, 2], after[:3, 3]
    step = o1 - o0
    if convention == 'standard':  # Rz(theta) Tz(d) Tx(a) Rx(alpha)
        return (_angle(x0, x1, z0), float(np.dot(step, z0)), float(np.dot(step, x1)),
                _angle(z0, z1, x1))
    # modified: Rx(alpha) Tx(a) Rz(theta) Tz(d)
    return (_angle(x0, x1, z1), float(np.dot(step, z1)), float(np.dot(step, x0)),
            _angle(z0, z1, x0))


def normal_feet(p1: np.ndarray, u1: np.ndarray, p2: np.ndarray,
                u2: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """
    Return ``(s, t)``: the common normal of two lines meets them at ``p1 + s u1``, ``p2 + t u2``.

    ``None`` for parallel lines. ``1 - (u1.u2)^2`` is computed as ``|u1 x u2|^2`` and the
    numerators as cross products: no cancellation for nearly parallel axes.
    """
    cross = np.cross(u1, u2)
    if np.linalg.norm(cross) < PARALLEL_TOL:
        return None
    w = p1 - p2
    denominator = np.dot(cross, cross)
    return (-np.dot(np.cross(u2, cross), w) / denominator,
            -np.dot(np.cross(u1, cross), w) / denominator)


__all__ = ['common_normal', 'dh_row', 'frames_on_axes', 'LENGTH_TOL_M', 'normal_feet',
           'PARALLEL_TOL']
