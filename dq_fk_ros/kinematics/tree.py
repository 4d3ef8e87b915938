"""
A tree of transforms (what TF carries), composed into every frame's pose in its root.

Plain Python floats with the dual-quaternion product of [Zivkovic2023] eq. (12); poses
cross this boundary as ``(x, y, z, qx, qy, qz, qw)`` (metres, the ROS quaternion order).
"""

from collections.abc import Mapping, Sequence
import math

from dq_fk_ros.kinematics.dual_quaternion import (
    Coeffs, dq_multiply_coeffs, Pose, pose_xyzw_from_coeffs)


def coeffs_from_pose(pose: Sequence[float]) -> Coeffs | None:
    """
    Return the 8 coefficients ``(w, x, y, z | w', x', y', z')`` of ``(x, y, z, qx..qw)``.

    The quaternion is normalised (TF senders round); ``r + eps t r / 2``, [Zivkovic2023] (7).
    A zero or non-finite quaternion gives None.
    """
    x, y, z, qx, qy, qz, qw = (float(v) for v in pose)
    norm = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    if not (norm > 0.0 and math.isfinite(norm) and math.isfinite(x + y + z)):
        return None
    w, qx, qy, qz = qw / norm, qx / norm, qy / norm, qz / norm
    # t r / 2 with t = (0, x, y, z)
    return (w, qx, qy, qz,
            0.5 * (-x * qx - y * qy - z * qz),
            0.5 * (x * w + y * qz - z * qy),
            0.5 * (-x * qz + y * w + z * qx),
            0.5 * (x * qy - y * qx + z * w))


def roots(edges: Mapping[str, tuple]) -> list[str]:
    """Return the frames that are some frame's parent and no frame's child, sorted."""
    return sorted({parent for parent, _ in edges.values()} - set(edges))


def compose_tree(edges: Mapping[str, tuple], root: str) -> dict[str, Pose]:
    """
    Return ``{frame: (x, y, z, qx, qy, qz, qw)}``: every frame below ``root``, posed in it.

    :param edges: ``{child: (parent, pose of child in parent)}`` (one parent per child, as
        TF keeps it); frames not connected to ``root``, and any cycle, are left out.
    """
    children = _children(edges)
    out = {}
    stack = [(root, (1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))]
    while stack:
        frame, pose = stack.pop()
        for child in children.get(frame, ()):
            if child in out or child == root:  # a cycle
                continue
            offset = coeffs_from_pose(edges[child][1])
            if offset is None:
                continue
            absolute = dq_multiply_coeffs(pose, offset)
            out[child] = pose_xyzw_from_coeffs(absolute)
            stack.append((child, absolute))
    return out


def depths(edges: Mapping[str, tuple], root: str) -> dict[str, int]:
    """Return ``{frame: number of transforms from root}`` of every frame below ``root``."""
    children = _children(edges)
    out, stack = {}, [(root, 0)]
    while stack:
        frame, depth = stack.pop()
        for child in children.get(frame, ()):
            if child not in out and child != root:
                out[child] = depth + 1
                stack.append((child, depth + 1))
    return out


def _children(edges):
    """Return ``{parent: [child, ...]}`` of ``{child: (parent, pose)}``."""
    children = {}
    for child, (parent, _) in edges.items():
        children.setdefault(parent, []).append(child)
    return children


__all__ = ['coeffs_from_pose', 'compose_tree', 'depths', 'roots']
