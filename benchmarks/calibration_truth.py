"""
The synthetic calibration data of bench_calibration.py, made with plain 4x4 DH products.

Numpy only (1.x and 2.x: the peers' venvs import it too). A robot file's table is
perturbed as a real arm is off its nominal one, placed in a tracker's frame, given a
reflector on its flange and measured (positions) with a tracker's noise; the data and the
noise-free truth of held-out configurations are saved in one ``.npz`` for every peer.
"""

import math

import numpy as np


def rot(axis, angle):
    c, s = math.cos(angle), math.sin(angle)
    m = np.eye(4)
    i, j = {'x': (1, 2), 'y': (2, 0), 'z': (0, 1)}[axis]
    m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
    return m


def trans(x, y, z):
    m = np.eye(4)
    m[:3, 3] = x, y, z
    return m


def frame(xyz, rpy):
    return trans(*xyz) @ rot('z', rpy[2]) @ rot('y', rpy[1]) @ rot('x', rpy[0])


def row_matrix(theta, d, a, alpha, convention):
    """One DH row: Spong's standard Rz Tz Tx Rx, or Craig's modified Rx Tx Rz Tz."""
    if convention == 'standard':
        return rot('z', theta) @ trans(0, 0, d) @ trans(a, 0, 0) @ rot('x', alpha)
    return rot('x', alpha) @ trans(a, 0, 0) @ rot('z', theta) @ trans(0, 0, d)


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
