"""sensor_msgs_py's point_cloud2 names (dq_fk_ros.ros.point_cloud2) and do_transform_cloud."""

import array
import copy
import struct
import sys

from dq_fk_ros.ros import point_cloud2 as pc2
from dq_fk_ros.ros.tf_cloud import do_transform_cloud, transform_points
from geometry_msgs.msg import Transform, TransformStamped
from hypothesis import given, strategies as st
import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import Header

F32, F64, U8 = PointField.FLOAT32, PointField.FLOAT64, PointField.UINT8


def hand_cloud(points, *, bigendian=False, pad_point=0, pad_row=0, rows=1, kind='f'):
    """Return a cloud packed here with struct: x y z (float32 or 64) and a uint8 label."""
    order = '>' if bigendian else '<'
    size = 4 if kind == 'f' else 8
    fields = [PointField(name=n, offset=k * size, datatype=F32 if kind == 'f' else F64,
                         count=1) for k, n in enumerate('xyz')]
    fields.append(PointField(name='label', offset=3 * size, datatype=U8, count=1))
    point_step = 3 * size + 1 + pad_point
    width = len(points) // rows
    row_step = width * point_step + pad_row
    data = bytearray()
    for r in range(rows):
        for x, y, z, label in points[r * width:(r + 1) * width]:
            data += struct.pack(f'{order}3{kind}B', x, y, z, label) + b'\xee' * pad_point
        data += b'\xdd' * pad_row
    cloud = PointCloud2(header=Header(frame_id='camera'), height=rows, width=width,
                        fields=fields, is_bigendian=bigendian, point_step=point_step,
                        row_step=row_step, is_dense=True)
    cloud.header.stamp.sec = 42
    cloud.data = array.array('B', bytes(data))
    return cloud


def unpack(cloud, kind='f'):
    """Return the cloud's (x, y, z, label) tuples read with struct (independent reader)."""
    order = '>' if cloud.is_bigendian else '<'
    raw = bytes(cloud.data)
    out = []
    for r in range(cloud.height):
        for c in range(cloud.width):
            at = r * cloud.row_step + c * cloud.point_step
            out.append(struct.unpack_from(f'{order}3{kind}B', raw, at))
    return out


POINTS = [(1.0, 2.0, 0.0, 7), (10.0, 20.0, 30.0, 9), (-1.5, 0.25, 4.0, 255), (0.0, 0.0, 1.0, 0)]


@pytest.mark.parametrize('bigendian', [False, True])
@pytest.mark.parametrize('pad_point, pad_row, rows', [(0, 0, 1), (3, 0, 1), (2, 5, 2)])
def test_read_points_reads_every_layout_without_changing_the_message(bigendian, pad_point,
                                                                     pad_row, rows):
    cloud = hand_cloud(POINTS, bigendian=bigendian, pad_point=pad_point, pad_row=pad_row,
                       rows=rows)
    before = bytes(cloud.data)
    points = pc2.read_points(cloud)
    assert [tuple(p) for p in points.tolist()] == POINTS
    assert points.dtype['x'].byteorder in '=<' if sys.byteorder == 'little' else '=>'
    assert bytes(cloud.data) == before   # sensor_msgs_py swaps a big-endian cloud in place
    assert pc2.read_points_numpy(cloud, field_names=['x', 'y', 'z']).tolist() == \
        [list(p[:3]) for p in POINTS]
    assert pc2.read_points_list(cloud)[2].label == 255


def test_organized_clouds_keep_their_rows_and_uvs_pick_points():
    cloud = hand_cloud(POINTS, rows=2)
    organized = pc2.read_points(cloud, reshape_organized_cloud=True)
    assert organized.shape == (2, 2)
    assert organized[1, 0]['label'] == 255
    assert pc2.read_points(cloud, uvs=[3, 0])['label'].tolist() == [0, 7]


def test_skip_nans_leaves_out_points_with_a_nan():
    cloud = hand_cloud([(1.0, 2.0, 3.0, 1), (float('nan'), 0.0, 0.0, 2), (4.0, 5.0, 6.0, 3)])
    cloud.is_dense = False
    assert pc2.read_points(cloud, skip_nans=True)['label'].tolist() == [1, 3]


@given(st.lists(st.tuples(*[st.floats(-1e3, 1e3, width=32)] * 3), max_size=40))
def test_create_cloud_xyz32_reads_back(points):
    cloud = pc2.create_cloud_xyz32(Header(frame_id='a'), np.array(points, np.float32)
                                   .reshape(-1, 3))
    assert (cloud.height, cloud.width, cloud.point_step) == (1, len(points), 12)
    assert [tuple(p) for p in pc2.read_points_numpy(cloud).tolist()] == \
        [tuple(float(np.float32(v)) for v in p) for p in points]


def test_create_cloud_takes_tuples_and_structured_arrays():
    fields = hand_cloud(POINTS).fields
    from_tuples = pc2.create_cloud(Header(), fields, POINTS)
    again = pc2.create_cloud(Header(), fields, pc2.read_points(from_tuples))
    assert bytes(again.data) == bytes(from_tuples.data)
    assert unpack(from_tuples) == POINTS


@pytest.mark.parametrize('change, words', [
    (lambda c: setattr(c, 'data', array.array('B', bytes(c.data)[:-1])), 'data has'),
    (lambda c: setattr(c, 'row_step', 3), 'row_step'),
    (lambda c: c.fields.__setitem__(0, PointField(name='x', offset=100, datatype=F32,
                                                  count=1)), 'past point_step'),
    (lambda c: c.fields.__setitem__(0, PointField(name='x', offset=0, datatype=9, count=1)),
     'datatype 9'),
    (lambda c: c.fields.__setitem__(1, PointField(name='x', offset=4, datatype=F32, count=1)),
     'twice'),
    (lambda c: setattr(c, 'width', 2 ** 31), 'row_step 52 is less than width'),
    (lambda c: setattr(c, 'height', 2 ** 31), 'data has'),
    (lambda c: c.fields.extend(PointField(name=f'f{k}', offset=0, datatype=U8, count=1000)
                               for k in range(2)), 'more than 1024 values a point'),
])
def test_a_cloud_whose_fields_and_data_disagree_is_refused_in_one_line(change, words):
    cloud = hand_cloud(POINTS)
    change(cloud)
    with pytest.raises(ValueError, match=words) as raised:
        pc2.read_points(cloud)
    assert '\n' not in str(raised.value)
    with pytest.raises(ValueError):
        do_transform_cloud(cloud, TransformStamped())


def stamped(q, t, frame='base'):
    msg = TransformStamped()
    msg.header.frame_id = frame
    msg.header.stamp.sec = 99
    r, p = msg.transform.rotation, msg.transform.translation
    r.x, r.y, r.z, r.w = q
    p.x, p.y, p.z = t
    return msg


quaternions = st.tuples(*[st.floats(-1, 1)] * 4).filter(lambda q: sum(v * v for v in q) > 0.1)


@given(quaternions, st.tuples(*[st.floats(-100, 100)] * 3), st.booleans(),
       st.sampled_from(['f', 'd']))
def test_a_cloud_is_moved_point_by_point_and_nothing_else_changes(q, t, bigendian, kind):
    cloud = hand_cloud(POINTS, bigendian=bigendian, pad_point=2, pad_row=3, rows=2, kind=kind)
    before = copy.deepcopy(cloud)
    out = do_transform_cloud(cloud, stamped(q, t))
    moved = Rotation.from_quat(q).apply([p[:3] for p in POINTS]) + np.array(t)
    got = unpack(out, kind)
    np.testing.assert_allclose([g[:3] for g in got], moved,
                               rtol=1e-6 if kind == 'f' else 1e-12, atol=1e-4)
    assert [g[3] for g in got] == [p[3] for p in POINTS]            # other fields as they were
    raw, old = bytes(out.data), bytes(cloud.data)
    pads = [k for k in range(len(raw)) if old[k] in (0xdd, 0xee) and
            (k % cloud.row_step >= cloud.width * cloud.point_step or
             k % cloud.row_step % cloud.point_step >= cloud.point_step - 2)]
    assert all(raw[k] == old[k] for k in pads)                      # padding too
    assert cloud == before                                          # the input untouched
    assert (out.header.frame_id, out.header.stamp.sec) == ('base', 42)   # the cloud's stamp
    assert (out.height, out.width, out.row_step, out.is_bigendian) == \
        (cloud.height, cloud.width, cloud.row_step, cloud.is_bigendian)


def test_a_bare_transform_keeps_the_clouds_frame_and_transform_points_is_float64():
    cloud = hand_cloud(POINTS)
    transform = Transform()
    transform.translation.z = 100.0
    transform.rotation.x, transform.rotation.w = 1.0, 0.0   # 180 degrees about x
    assert do_transform_cloud(cloud, transform).header.frame_id == 'camera'
    points = transform_points(np.array([[1, 2, 0], [10, 20, 30]], np.float32), transform)
    assert points.dtype == np.float64
    assert points.tolist() == [[1, -2, 100], [10, -20, 70]]


def test_a_cloud_without_xyz_is_refused():
    cloud = hand_cloud(POINTS)
    cloud.fields = [cloud.fields[3]]
    with pytest.raises(ValueError, match='x, y and z'):
        do_transform_cloud(cloud, TransformStamped())
