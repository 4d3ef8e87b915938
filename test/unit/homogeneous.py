"""
An independent 4x4 homogeneous-matrix reference for the tests.

Written from the textbook definitions (Spong for standard DH, Craig for modified DH,
Rodrigues for rotations); it shares no code with :mod:`dq_fk_ros`.
"""

import numpy as np


def rot_x(angle):
    """Rotation about x by ``angle`` rad."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def rot_z(angle):
    """Rotation about z by ``angle`` rad."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def rot_y(angle):
    """Rotation about y by ``angle`` rad."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def trans(x=0.0, y=0.0, z=0.0):
    """Pure translation."""
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def rodrigues(axis, angle):
    """4x4 rotation about the unit vector ``axis`` by ``angle`` rad (Rodrigues' formula)."""
    k = np.asarray(axis, dtype=float)
    k = k / np.linalg.norm(k)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    m = np.eye(4)
    m[:3, :3] = np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx
    return m


def dh_standard(theta, d, a, alpha):
    """Spong's A_i = Rz(theta) Tz(d) Tx(a) Rx(alpha), written out element by element."""
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array([[ct, -st * ca, st * sa, a * ct],
                     [st, ct * ca, -ct * sa, a * st],
                     [0, sa, ca, d],
                     [0, 0, 0, 1.0]])


def dh_modified(theta, d, a, alpha):
    """Craig's T_i = Rx(alpha) Tx(a) Rz(theta) Tz(d), written out element by element."""
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array([[ct, -st, 0, a],
                     [st * ca, ct * ca, -sa, -sa * d],
                     [st * sa, ct * sa, ca, ca * d],
                     [0, 0, 0, 1.0]])


def chain_frames(rows, convention, base=None, tool=None):
    """
    Absolute 4x4 frames 0..n (then the tool) of rows ``(theta, d, a, alpha)``.

    :param rows: the DH table already evaluated at a configuration.
    """
    step = dh_standard if convention == 'standard' else dh_modified
    acc = np.eye(4) if base is None else np.asarray(base, dtype=float)
    frames = [acc]
    for theta, d, a, alpha in rows:
        acc = acc @ step(theta, d, a, alpha)
        frames.append(acc)
    if tool is not None:
        frames.append(acc @ tool)
    return frames


def matrix_of_pose(position, quat_xyzw):
    """4x4 matrix from a position and a unit quaternion (x, y, z, w), via Rodrigues."""
    x, y, z, w = quat_xyzw
    vec = np.array([x, y, z])
    s = np.linalg.norm(vec)
    m = np.eye(4) if s < 1e-15 else rodrigues(vec, 2 * np.arctan2(s, w))
    m[:3, 3] = position
    return m
