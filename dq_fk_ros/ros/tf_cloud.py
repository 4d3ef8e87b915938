"""
tf2_sensor_msgs: a ``sensor_msgs/PointCloud2`` moved by a transform, in numpy.

``do_transform_cloud(cloud, transform)`` and ``transform_points(points, transform)`` as
geometry2's ``tf2_sensor_msgs`` (Jazzy) name them: x, y and z of every point rotated and
translated, every other field as it was, the header's frame the transform's target (a
``TransformStamped``) and its stamp the cloud's. Registered for ``Buffer.transform``, so
``buffer.transform(cloud, 'base_link')`` is "the camera's cloud in the base frame".

One copy of the message's bytes, then x, y, z read as float64 rows through a strided view,
moved by the rotation matrix and the translation in place (no BLAS: a threaded matrix product
waits on a busy core), and written back in their own type: no per-point Python, no
structured-array round trip (benchmarks/bench_tf.py (f) compares it with tf2_sensor_msgs').
"""

import array

from dq_fk_ros.ros.point_cloud2 import cloud_view, dtype_from_fields
from dq_fk_ros.ros.tf_registration import ConvertRegistration, TransformRegistration
from geometry_msgs.msg import TransformStamped
import numpy as np
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Header


def rotation_matrix(rotation) -> np.ndarray:
    """Return the 3x3 matrix of a quaternion message (x y z w), normalised; identity if 0."""
    x, y, z, w = rotation.x, rotation.y, rotation.z, rotation.w
    n = x * x + y * y + z * z + w * w
    if not n > 2.220446049250313e-16:
        return np.eye(3)
    s = 2.0 / n
    return np.array([[1 - s * (y * y + z * z), s * (x * y - w * z), s * (x * z + w * y)],
                     [s * (x * y + w * z), 1 - s * (x * x + z * z), s * (y * z - w * x)],
                     [s * (x * z - w * y), s * (y * z + w * x), 1 - s * (x * x + y * y)]])


def transform_points(point_cloud: np.ndarray, transform) -> np.ndarray:
    """Return (N, 3) ``point_cloud`` moved by a ``geometry_msgs/Transform`` (float64)."""
    t = transform.translation
    points = np.asarray(point_cloud, dtype=np.float64)
    return points @ rotation_matrix(transform.rotation).T + np.array([t.x, t.y, t.z])


def do_transform_cloud(cloud: PointCloud2, transform) -> PointCloud2:
    """
    Return ``cloud`` moved by ``transform`` (a ``Transform`` or ``TransformStamped``).

    :raises ValueError: a cloud without x, y and z fields of one value each, or whose fields
        and data do not agree (one line).
    """
    header = Header(frame_id=cloud.header.frame_id)
    header.stamp.sec, header.stamp.nanosec = cloud.header.stamp.sec, cloud.header.stamp.nanosec
    if isinstance(transform, TransformStamped):
        header.frame_id = transform.header.frame_id
        transform = transform.transform
    dtype = dtype_from_fields(cloud.fields, cloud.point_step, cloud.is_bigendian)
    if not {'x', 'y', 'z'} <= set(dtype.names):
        raise ValueError('PointCloud2: the fields x, y and z are needed for a transform')
    cloud_view(cloud, dtype)   # checks the data against the rows first
    data = array.array('B', cloud.data)   # the one copy: every other field as it was
    out = PointCloud2(header=header, height=cloud.height, width=cloud.width,
                      fields=cloud.fields, is_bigendian=cloud.is_bigendian,
                      point_step=cloud.point_step, row_step=cloud.row_step,
                      is_dense=cloud.is_dense)
    out.data = data
    view = cloud_view(out, dtype)
    rows = view.shape[0] * view.shape[1]
    xyz = np.empty((3, rows))   # one contiguous row a coordinate
    for k, name in enumerate('xyz'):
        xyz[k] = view[name].reshape(rows)
    moved, term = np.empty((3, rows)), np.empty(rows)
    r, t = rotation_matrix(transform.rotation), transform.translation
    for i, shift in enumerate((t.x, t.y, t.z)):   # moved = R xyz + t, row by row, in place
        row = moved[i]
        np.multiply(xyz[0], r[i, 0], out=row)
        np.multiply(xyz[1], r[i, 1], out=term)
        row += term
        np.multiply(xyz[2], r[i, 2], out=term)
        row += term
        row += shift
    for k, name in enumerate('xyz'):
        view[name] = moved[k].reshape(view.shape)
    return out


def to_msg_msg(msg) -> object:
    """Return ``msg`` (geometry2's)."""
    return msg


def from_msg_msg(msg) -> object:
    """Return ``msg`` (geometry2's)."""
    return msg


TransformRegistration().add_default(PointCloud2, do_transform_cloud)
ConvertRegistration().add_to_msg(PointCloud2, to_msg_msg)
ConvertRegistration().add_from_msg(PointCloud2, from_msg_msg)

__all__ = ['do_transform_cloud', 'from_msg_msg', 'rotation_matrix', 'to_msg_msg',
           'transform_points']
