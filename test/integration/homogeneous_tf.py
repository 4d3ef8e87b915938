"""Compose TransformStamped lists with plain 4x4 matrices (independent of dq_fk_ros)."""

import numpy as np


def quat_matrix(x, y, z, w):
    """Rotation matrix of a unit quaternion (x, y, z, w)."""
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def transform_matrix(transform):
    """4x4 of a geometry_msgs/Transform."""
    t, r = transform.translation, transform.rotation
    return pose_matrix_of_tuple((t.x, t.y, t.z, r.x, r.y, r.z, r.w))


def pose_matrix(pose):
    """4x4 of a geometry_msgs/Pose."""
    p, o = pose.position, pose.orientation
    return pose_matrix_of_tuple((p.x, p.y, p.z, o.x, o.y, o.z, o.w))


def parent_of(transforms, child):
    """Parent frame id of ``child`` in a list of TransformStamped."""
    return {t.child_frame_id: t.header.frame_id for t in transforms}[child]


def compose(transforms, root, frame):
    """Pose of ``frame`` in ``root``, walking child -> parent through ``transforms``."""
    by_child = {t.child_frame_id: t for t in transforms}
    m = np.eye(4)
    while frame != root:
        t = by_child[frame]
        m = transform_matrix(t.transform) @ m
        frame = t.header.frame_id
    return m


def pose_matrix_of_tuple(pose):
    """4x4 of ``(x, y, z, qx, qy, qz, qw)``."""
    m = np.eye(4)
    m[:3, :3] = quat_matrix(*pose[3:])
    m[:3, 3] = pose[:3]
    return m
