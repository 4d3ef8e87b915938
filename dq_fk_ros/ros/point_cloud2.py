"""
``sensor_msgs/PointCloud2`` to and from numpy: sensor_msgs_py's ``point_cloud2`` names.

common_interfaces' pure-Python ``sensor_msgs_py`` is not on PyPI; code written for it (and
tf2_sensor_msgs) calls ``read_points``, ``read_points_numpy``, ``read_points_list``,
``create_cloud``, ``create_cloud_xyz32`` and ``dtype_from_fields``, with the same arguments
here. The compat path (``dq_fk tf compat-path``) offers this module as
``sensor_msgs_py.point_cloud2`` where the venv has none.

Not as sensor_msgs_py: a cloud from the wire is checked before it is read (a field past the
point, a data array shorter than its rows say, an unknown datatype: one-line ``ValueError``),
reading never modifies the message (sensor_msgs_py byte-swaps a foreign-endian cloud's data
in place), rows with padding (``row_step`` > ``width * point_step``) are read, and an
organized cloud's array is (height, width), rows first, as the message lays its points out
(sensor_msgs_py makes it (width, height)).
"""

import array
from collections import namedtuple
import sys

import numpy as np
from sensor_msgs.msg import PointCloud2, PointField

DATATYPES = {PointField.INT8: np.int8, PointField.UINT8: np.uint8,
             PointField.INT16: np.int16, PointField.UINT16: np.uint16,
             PointField.INT32: np.int32, PointField.UINT32: np.uint32,
             PointField.FLOAT32: np.float32, PointField.FLOAT64: np.float64}
DUMMY_FIELD_PREFIX = 'unnamed_field'
MAX_FIELDS = 1024   # values a point at most (fields times counts): each a numpy field


def dtype_from_fields(fields, point_step=None, bigendian: bool = False) -> np.dtype:
    """
    Return the structured numpy dtype of one point of ``fields``.

    A field of ``count`` k > 1 gives fields ``name_0`` ... ``name_k-1``; a field without a
    name is ``unnamed_field_<index>``. ``point_step``: the item size (default: the fields').
    """
    fields = list(fields)
    if len(fields) > MAX_FIELDS:
        raise ValueError(f'PointCloud2 fields: {len(fields)}, at most {MAX_FIELDS} read')
    names, formats, offsets = [], [], []
    order = '>' if bigendian else '<'
    for i, field in enumerate(fields):
        kind = DATATYPES.get(field.datatype)
        if kind is None:
            raise ValueError(f'PointCloud2 field {i}: datatype {field.datatype} is none of '
                             'PointField INT8 ... FLOAT64 (1-8)')
        if field.count < 1:
            raise ValueError(f'PointCloud2 field {i}: count {field.count}, at least 1')
        if field.count > MAX_FIELDS:
            raise ValueError(f'PointCloud2 field {i}: count {field.count}, at most '
                             f'{MAX_FIELDS}')
        if len(names) + field.count > MAX_FIELDS:
            raise ValueError(f'PointCloud2 field {i}: more than {MAX_FIELDS} values a point '
                             '(fields times their counts)')
        kind = np.dtype(kind).newbyteorder(order)
        name = field.name or f'{DUMMY_FIELD_PREFIX}_{i}'
        for k in range(field.count):
            sub = f'{name}_{k}' if field.count > 1 else name
            if sub in names:
                raise ValueError(f'PointCloud2 field {i}: the name {sub[:64]!r} twice')
            names.append(sub)
            formats.append(kind)
            offsets.append(field.offset + k * kind.itemsize)
    spec = {'names': names, 'formats': formats, 'offsets': offsets}
    if point_step is not None:
        end = max((o + f.itemsize for o, f in zip(offsets, formats)), default=0)
        if end > point_step:
            raise ValueError(f'PointCloud2: a field ends at byte {end}, past point_step '
                             f'{point_step}')
        spec['itemsize'] = point_step
    return np.dtype(spec)


def cloud_view(cloud, dtype=None) -> np.ndarray:
    """
    Return the cloud's points as a (height, width) structured array over ``cloud.data``.

    A view (no copy) of the message's own buffer; checked against the data's length first.
    """
    if dtype is None:
        dtype = dtype_from_fields(cloud.fields, cloud.point_step, cloud.is_bigendian)
    height, width = int(cloud.height), int(cloud.width)
    row_step, point_step = int(cloud.row_step), int(cloud.point_step)
    data = cloud.data
    size = len(data)
    if height and width:
        if row_step < width * point_step:
            raise ValueError(f'PointCloud2: row_step {row_step} is less than width {width} x '
                             f'point_step {point_step}')
        need = (height - 1) * row_step + width * point_step
        if need > size:
            raise ValueError(f'PointCloud2: {height} rows of {width} points need {need} '
                             f'bytes, data has {size}')
    else:
        height, width = 0, 0
    buffer = data if size else b'\0' * max(point_step, 1)
    return np.ndarray((height, width), dtype, buffer, 0, (row_step, point_step))


def read_points(cloud, field_names=None, skip_nans: bool = False, uvs=None,
                reshape_organized_cloud: bool = False) -> np.ndarray:
    """
    Return the points as a structured array (a copy, in this machine's byte order).

    :param field_names: the fields to read (default: all).
    :param skip_nans: leave out points with a NaN in a field read (clouds not dense).
    :param uvs: indices of the points to read (after ``skip_nans``).
    :param reshape_organized_cloud: keep the (height, width) shape of an organized cloud.
    """
    if not isinstance(cloud, PointCloud2):
        raise TypeError(f'a PointCloud2 is read, not {type(cloud).__name__}')
    view = cloud_view(cloud)
    if field_names is not None:
        missing = [n for n in field_names if n not in view.dtype.names]
        if missing:
            raise ValueError(f'PointCloud2 has no field {str(missing[0])[:64]!r}')
        view = view[list(field_names)]
    native = np.dtype([(n, view.dtype.fields[n][0].newbyteorder('='))
                       for n in view.dtype.names])
    shape = view.shape
    points = np.empty(shape, native)
    for name in native.names:
        points[name] = view[name]
    points = points.reshape(-1)
    if skip_nans and not cloud.is_dense:
        keep = np.ones(len(points), bool)
        for name in native.names:
            if points.dtype[name].kind == 'f':
                keep &= ~np.isnan(points[name])
        points = points[keep]
    if uvs is not None:
        points = points[np.asarray(uvs if isinstance(uvs, np.ndarray) else list(uvs), int)]
    elif reshape_organized_cloud and shape[0] > 1 and not (skip_nans and not cloud.is_dense):
        points = points.reshape(shape)
    return points


def read_points_numpy(cloud, field_names=None, skip_nans: bool = False, uvs=None,
                      reshape_organized_cloud: bool = False) -> np.ndarray:
    """Return the points as a plain (N, fields) array; every field read of one datatype."""
    chosen = [f for f in cloud.fields if field_names is None or f.name in field_names]
    if len({f.datatype for f in chosen}) > 1:
        raise ValueError('PointCloud2: fields of several datatypes; read_points reads them')
    points = read_points(cloud, field_names, skip_nans, uvs, reshape_organized_cloud)
    names = points.dtype.names
    kind = points.dtype[names[0]] if names else np.dtype(np.float32)
    out = np.empty(points.shape + (len(names),), kind)
    for k, name in enumerate(names):
        out[..., k] = points[name]
    return out


def read_points_list(cloud, field_names=None, skip_nans: bool = False, uvs=None) -> list:
    """Return the points as a list of namedtuples ``Point(x=..., ...)``."""
    points = read_points(cloud, field_names, skip_nans, uvs)
    point = namedtuple('Point', points.dtype.names, rename=True)
    return [point._make(p) for p in points.tolist()]


def create_cloud(header, fields, points, point_step=None) -> PointCloud2:
    """
    Return a ``PointCloud2`` of ``points`` with ``fields``.

    :param points: a structured array of the fields' dtype, a plain (N, fields) or
        (height, width, fields) array of one datatype, or an iterable of per-point tuples.
    """
    fields = list(fields)
    dtype = dtype_from_fields(fields, point_step, sys.byteorder != 'little')
    if isinstance(points, np.ndarray) and points.dtype.names is None:
        plain = np.asarray(points)
        if plain.shape[-1:] != (len(dtype.names),) or plain.ndim > 3:
            raise ValueError(f'PointCloud2: points of shape {plain.shape}, expected (N, '
                             f'{len(dtype.names)}) or (height, width, {len(dtype.names)})')
        structured = np.zeros(plain.shape[:-1], dtype)
        for k, name in enumerate(dtype.names):
            structured[name] = plain[..., k]
    elif isinstance(points, np.ndarray):
        structured = np.zeros(points.shape, dtype)
        for name in dtype.names:
            structured[name] = points[name]
    else:
        structured = np.array([tuple(p) for p in points], dtype)
    if structured.ndim > 2:
        raise ValueError('PointCloud2: points in more than two dimensions')
    height, width = (1, structured.shape[0]) if structured.ndim == 1 else structured.shape
    data = array.array('B')
    data.frombytes(np.ascontiguousarray(structured).tobytes())
    cloud = PointCloud2(header=header, height=height, width=width, is_dense=False,
                        is_bigendian=sys.byteorder != 'little', fields=fields,
                        point_step=dtype.itemsize, row_step=dtype.itemsize * width)
    cloud.data = data
    return cloud


def create_cloud_xyz32(header, points) -> PointCloud2:
    """Return a ``PointCloud2`` of float32 x, y, z fields from (N, 3) ``points``."""
    fields = [PointField(name=n, offset=4 * k, datatype=PointField.FLOAT32, count=1)
              for k, n in enumerate('xyz')]
    return create_cloud(header, fields, points)


__all__ = ['cloud_view', 'create_cloud', 'create_cloud_xyz32', 'DATATYPES',
           'dtype_from_fields', 'DUMMY_FIELD_PREFIX', 'read_points', 'read_points_list',
           'read_points_numpy']
