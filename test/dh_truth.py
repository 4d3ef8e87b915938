"""
A DH robot's poses as the textbooks compute them: plain 4x4 products, no code of the package.

The truth of test_calibration.py and test_calibration_bag.py (a perturbed robot measured by
a tracker), and of benchmarks/bench_calibration.py's data for dq_fk calibrate's peers.
"""

import math

import numpy as np


def rot(axis, angle):
    """Return the 4x4 rotation about ``axis`` (x, y or z) by ``angle`` rad."""
    c, s = math.cos(angle), math.sin(angle)
    m = np.eye(4)
    i, j = {'x': (1, 2), 'y': (2, 0), 'z': (0, 1)}[axis]
    m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
    return m


def trans(x, y, z):
    """Return the 4x4 translation by ``(x, y, z)``."""
    m = np.eye(4)
    m[:3, 3] = x, y, z
    return m


def row_matrix(theta, d, a, alpha, convention):
    """Return one DH row, as the textbooks multiply it (Spong standard, Craig modified)."""
    if convention == 'standard':
        return rot('z', theta) @ trans(0, 0, d) @ trans(a, 0, 0) @ rot('x', alpha)
    return rot('x', alpha) @ trans(a, 0, 0) @ rot('z', theta) @ trans(0, 0, d)


def frame_matrix(xyz, rpy):
    """Return the 4x4 of a position and roll, pitch, yaw (URDF's fixed-axis order)."""
    return trans(*xyz) @ rot('z', rpy[2]) @ rot('y', rpy[1]) @ rot('x', rpy[0])


def positions(rows, convention, base, tool, world, end, q):
    """Return the measured point's positions ``(M, 3)`` at the configurations ``q``."""
    out = []
    for values in q:
        m = world @ base
        for (theta, d, a, alpha), v in zip(rows, values):
            m = m @ row_matrix(theta + v, d, a, alpha, convention)
        out.append((m @ tool @ end)[:3, 3])
    return np.array(out)


def kabsch(source, target):
    """Return the 4x4 rigid motion taking points ``source`` closest to ``target``."""
    a, b = source - source.mean(0), target - target.mean(0)
    u, _, vt = np.linalg.svd(b.T @ a)
    r = u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))]) @ vt
    m = np.eye(4)
    m[:3, :3] = r
    m[:3, 3] = target.mean(0) - r @ source.mean(0)
    return m
