"""
A bag's TF read into a buffer (dq_fk_ros.bag.tf_bag, dq_fk_ros.tf.buffer_from_bag).

The bags are written here with rosbags (rosbag2 MCAP and sqlite3, ROS 1) and the mcap
library's file taken out of the rosbag2 folder (a bare .mcap); the reference is the same
transforms given one by one, in the order written, to BufferCore.set_transform.
"""

import math
import shutil

from dq_fk_ros import tf
from dq_fk_ros.bag.tf_bag import core_from_bag
from dq_fk_ros.errors import BagError
from dq_fk_ros.transforms.buffer_core import BufferCore
from dq_fk_ros.transforms.exceptions import TransformException
from hypothesis import given, strategies as st
import numpy as np
import pytest
from rosbags.typesys import get_types_from_msg, get_typestore, Stores

pytestmark = pytest.mark.integration
TS2, TS1 = get_typestore(Stores.ROS2_JAZZY), get_typestore(Stores.ROS1_NOETIC)
TS1.register(get_types_from_msg('geometry_msgs/TransformStamped[] transforms',
                                'tf2_msgs/msg/TFMessage'))
TF = 'tf2_msgs/msg/TFMessage'
T0 = 1_700_000_000 * 10**9
MS = 10**6


def recording():
    """Return ``[(topic, log time, [(parent, child, stamp, pose)])]`` of a small robot."""
    out = [('/tf_static', T0, [('world', 'base', 0, (0, 0, 0.5, 0, 0, 0, 1)),
                               ('/hand', '/camera', 0, (0, 0, 0.1, 0.5, 0.5, 0.5, 0.5))])]
    for k in range(200):
        t = T0 + 10 * MS * k
        a = 0.01 * k
        arm = (0.1, 0, 0, 0, math.sin(a / 2), 0, math.cos(a / 2))
        hand = (0.3, 0, 0, 0, 0, math.sin(a), math.cos(a))
        out.append(('/tf', t, [('base', 'arm', t, arm), ('arm', 'hand', t, hand)]))
        if k % 7 == 0:   # another publisher, another layout: odometry
            out.append(('/tf', t + MS, [('map', 'world', t + MS, (k * 0.01, 0, 0, 0, 0, 0, 1))]))
    out.append(('/tf', T0 + 3 * MS, [('base', 'arm', T0 + 3 * MS, (9, 9, 9, 0, 0, 0, 1))]))
    out.append(('/tf', T0 + 4 * MS, [('base', 'arm', T0 + 4 * MS,
                                      (math.nan, 0, 0, 0, 0, 0, 1))]))   # refused
    out.append(out[5])   # a message recorded twice
    t = T0 + 10 * MS * 3   # another arm at a stamp its edge holds: refused (TF_REPEATED_DATA)
    out.append(('/tf', t + MS // 2, [('base', 'arm', t, (7, 7, 7, 0, 0, 0, 1))]))
    return out


def message(store, transforms, ros1=False):
    types = store.types
    header = types['std_msgs/msg/Header']
    time = types['builtin_interfaces/msg/Time']

    def head(parent, stamp):
        extra = {'seq': 0} if ros1 else {}
        return header(stamp=time(sec=stamp // 10**9, nanosec=stamp % 10**9), frame_id=parent,
                      **extra)
    return types[TF](transforms=[types['geometry_msgs/msg/TransformStamped'](
        header=head(parent, stamp), child_frame_id=child,
        transform=types['geometry_msgs/msg/Transform'](
            translation=types['geometry_msgs/msg/Vector3'](x=p[0], y=p[1], z=p[2]),
            rotation=types['geometry_msgs/msg/Quaternion'](x=p[3], y=p[4], z=p[5], w=p[6])))
        for parent, child, stamp, p in transforms])


def write_bag(path, kind):
    rows = recording()
    if kind == 'ros1':
        from rosbags.rosbag1 import Writer
        with Writer(path) as writer:
            conns = {t: writer.add_connection(t, TF, typestore=TS1) for t in ('/tf', '/tf_static')}
            for topic, log_time, transforms in rows:
                writer.write(conns[topic], log_time,
                             TS1.serialize_ros1(message(TS1, transforms, True), TF))
        return path
    from rosbags.rosbag2 import StoragePlugin, Writer
    storage = StoragePlugin.SQLITE3 if kind == 'sqlite3' else StoragePlugin.MCAP
    folder = path if kind != 'bare' else path.parent / 'folder'
    with Writer(folder, version=9, storage_plugin=storage) as writer:
        conns = {t: writer.add_connection(t, TF, typestore=TS2) for t in ('/tf', '/tf_static')}
        for topic, log_time, transforms in rows:
            writer.write(conns[topic], log_time, bytes(TS2.serialize_cdr(
                message(TS2, transforms), TF)))
    if kind == 'bare':
        shutil.copy(next(folder.glob('*.mcap')), path)
    return path


def reference():
    core = BufferCore(1 << 62)
    for topic, _, transforms in recording():
        for parent, child, stamp, pose in transforms:
            core.set_transform(parent, child, stamp, pose, 'bag', topic == '/tf_static')
    return core


QUERIES = [('map', 'camera'), ('world', 'hand'), ('camera', 'base'), ('arm', 'hand')]
STAMPS = [0, T0, T0 + 3 * MS, T0 + 5 * MS, T0 + 10 * MS * 50 + 3333, T0 + 10 * MS * 199,
          T0 + 10 * MS * 199 + 1, T0 - 1]


@pytest.mark.parametrize('kind', ['mcap', 'sqlite3', 'ros1', 'bare'])
def test_every_format_reads_as_the_transforms_given_one_by_one(tmp_path, kind):
    name = {'ros1': 'tf.bag', 'bare': 'tf.mcap'}.get(kind, 'tf_bag')
    path = write_bag(tmp_path / name, kind)
    core, summary = core_from_bag(path)
    expected = reference()
    assert summary.refused == 1 and summary.duplicates == 2   # (two transforms recorded twice)
    assert summary.repeated == 1
    for target, source in QUERIES:
        for stamp in STAMPS:
            try:
                want = expected.lookup(target, source, stamp)
            except TransformException as exc:
                with pytest.raises(type(exc)):
                    core.lookup(target, source, stamp)
                continue
            got = core.lookup(target, source, stamp)
            assert got[1] == want[1]
            np.testing.assert_allclose(got[0], want[0], atol=1e-12, err_msg=str((target,
                                                                                source, stamp)))
    buffer = tf.buffer_from_bag(path)
    stamps = [T0 + 10 * MS * k + 7 for k in range(-2, 203)]
    rows = buffer.lookup_poses('world', 'camera', stamps)
    for row, stamp in zip(rows, stamps):
        try:
            np.testing.assert_allclose(row, expected.lookup('world', 'camera', stamp)[0],
                                       atol=1e-12)
        except TransformException:
            assert np.isnan(row).all()
    assert np.isnan(rows).all(axis=1).sum() == 2 + 4   # before the first, after the last


def test_start_and_end_bound_what_is_read_and_too_much_is_one_line(tmp_path):
    path = write_bag(tmp_path / 'tf_bag', 'mcap')
    core, _ = core_from_bag(path, start=T0 + 10 * MS * 100, end=T0 + 10 * MS * 150)
    assert core.lookup('world', 'hand', T0 + 10 * MS * 120)
    with pytest.raises(TransformException):
        core.lookup('world', 'hand', T0 + 10 * MS * 99)
    assert core.lookup('world', 'camera', T0 + 10 * MS * 120)   # statics: always read whole
    with pytest.raises(BagError, match='give start and end') as info:
        core_from_bag(path, max_transforms=100)
    assert '\n' not in str(info.value)
    with pytest.raises(BagError, match=r'has no /tf or /tf_static'):
        empty = tmp_path / 'none'
        from rosbags.rosbag2 import Writer
        with Writer(empty, version=9) as writer:
            writer.add_connection('/chatter', 'std_msgs/msg/String', typestore=TS2)
        core_from_bag(empty)


def test_dq_fk_bag_tf_writes_the_pose_at_a_rate_and_at_a_topics_stamps(tmp_path, capsys):
    import csv
    from dq_fk_ros.cli.dq_fk_bag import main
    from rosbags.rosbag2 import Writer
    path = tmp_path / 'tf_bag'
    write_bag(path, 'mcap')
    assert main(['tf', str(path), 'world', 'hand', '--csv', str(tmp_path / 'a.csv'),
                 '--rate', '50']) == 0
    out = capsys.readouterr().out
    rows = list(csv.reader(open(tmp_path / 'a.csv')))
    assert rows[0] == ['stamp_ns', 'x', 'y', 'z', 'qx', 'qy', 'qz', 'qw']
    assert len(rows) - 1 == 100 and out.startswith(f'{tmp_path / "a.csv"}: 100 poses')
    expected = reference()
    for row in rows[1:]:
        np.testing.assert_allclose([float(v) for v in row[1:]],
                                   expected.lookup('world', 'hand', int(row[0]))[0], atol=5e-10)
    # at each image's stamp: one image before TF starts is left out, and said so
    images = tmp_path / 'images'
    with Writer(images, version=9) as writer:
        conn = writer.add_connection('/camera/image', 'sensor_msgs/msg/Image', typestore=TS2)
        tf_conn = writer.add_connection('/tf', TF, typestore=TS2)
        for topic, log_time, transforms in recording():
            if topic == '/tf':
                writer.write(tf_conn, log_time, bytes(TS2.serialize_cdr(
                    message(TS2, transforms), TF)))
        image = TS2.types['sensor_msgs/msg/Image']
        header = TS2.types['std_msgs/msg/Header']
        time = TS2.types['builtin_interfaces/msg/Time']
        for k, stamp in enumerate((T0 - 10 * MS, T0 + 333 * MS, T0 + 1500 * MS + 1)):
            msg = image(header=header(stamp=time(sec=stamp // 10**9, nanosec=stamp % 10**9),
                                      frame_id='camera'), height=1, width=1, encoding='mono8',
                        is_bigendian=0, step=1, data=np.zeros(1, np.uint8))
            writer.write(conn, T0 + k, bytes(TS2.serialize_cdr(msg, 'sensor_msgs/msg/Image')))
    assert main(['tf', str(images), 'base', 'hand', '--csv', str(tmp_path / 'b.csv'),
                 '--at-topic', '/camera/image']) == 0
    assert '2 poses of hand in base; 1 stamps TF could not answer' in capsys.readouterr().out
    rows = list(csv.reader(open(tmp_path / 'b.csv')))[1:]
    assert [int(r[0]) for r in rows] == [T0 + 333 * MS, T0 + 1500 * MS + 1]
    assert main(['tf', str(images), 'base', 'hand', '--csv', str(tmp_path / 'c.csv'),
                 '--at-topic', '/tf']) == 2
    assert 'is not one whose first field is a std_msgs/Header' in capsys.readouterr().err


def test_dq_fk_tf_frames_draws_a_bags_tree(tmp_path, capsys):
    from dq_fk_ros.cli.dq_fk import main
    path = write_bag(tmp_path / 'tf_bag', 'mcap')
    assert main(['tf', 'frames', '--bag', str(path), '-o', str(tmp_path / 'f.pdf')]) == 0
    text = open(tmp_path / 'f.gv').read()
    for edge in ('"world" -> "base"', '"base" -> "arm"', '"arm" -> "hand"', '"map" -> "world"',
                 '"hand" -> "camera"'):
        assert edge in text
    # tf2's rate: samples over the span, 201 (200 and one out of order) in 1.99 s
    assert 'Average rate: 101.005 Hz' in text.split('"base" -> "arm"')[1].split('\n')[0]
    assert open(tmp_path / 'f.pdf', 'rb').read(5) == b'%PDF-'


@given(st.lists(st.tuples(st.integers(-2**63, 2**63 - 1),
                          st.lists(st.floats(allow_nan=True), min_size=7, max_size=7)),
                max_size=20))
def test_csv_rows_are_the_python_ones(rows):
    """The C writer's characters are fixed9's: 9 decimals, within 5e-10 of the value."""
    from dq_fk_ros.bag import tf_export
    stamps = np.array([r[0] for r in rows], np.int64)
    poses = np.array([r[1] for r in rows], np.float64).reshape(-1, 7)
    expected = ''.join(f'{s},' + ','.join(tf_export.fixed9(v) for v in p) + '\n'
                       for s, p in zip(stamps.tolist(), poses.tolist()))
    assert tf_export.csv_rows(stamps, poses) == expected
    for line, pose in zip(expected.splitlines(), poses.tolist()):
        for text, value in zip(line.split(',')[1:], pose):
            if math.isfinite(value) and abs(value) < 9e9:   # (a float near 9e9 is 1e-6 apart)
                assert abs(float(text) - value) <= 5e-10 + abs(value) * 2e-16


def test_at_topic_holds_at_most_max_rows_stamps(tmp_path):
    """A bag with more messages on the topic than rows allowed is refused in one line."""
    from dq_fk_ros.bag.tf_export import stamps_of_topic
    from rosbags.rosbag2 import Writer
    images = tmp_path / 'images'
    with Writer(images, version=9) as writer:
        conn = writer.add_connection('/camera/image', 'sensor_msgs/msg/Image', typestore=TS2)
        image = TS2.types['sensor_msgs/msg/Image']
        header = TS2.types['std_msgs/msg/Header']
        time = TS2.types['builtin_interfaces/msg/Time']
        for k in range(20):
            msg = image(header=header(stamp=time(sec=k, nanosec=0), frame_id='camera'),
                        height=0, width=0, encoding='mono8', is_bigendian=0, step=0,
                        data=np.zeros(0, np.uint8))
            writer.write(conn, T0 + k, bytes(TS2.serialize_cdr(msg, 'sensor_msgs/msg/Image')))
    blocks = list(stamps_of_topic(images, '/camera/image', max_rows=20, block=8))
    assert [len(b) for b in blocks] == [8, 8, 4]
    assert np.concatenate(blocks).tolist() == [k * 10**9 for k in range(20)]
    with pytest.raises(BagError, match='more than 19 messages') as info:
        list(stamps_of_topic(images, '/camera/image', max_rows=19))
    assert '\n' not in str(info.value)


def tf_bag_of(path, messages):
    """Write ``[(log time, [(parent, child, stamp, pose)])]`` on /tf as a rosbag2 MCAP bag."""
    from rosbags.rosbag2 import Writer
    with Writer(path, version=9) as writer:
        conn = writer.add_connection('/tf', TF, typestore=TS2)
        for log_time, transforms in messages:
            writer.write(conn, log_time, bytes(TS2.serialize_cdr(message(TS2, transforms), TF)))
    return path


def test_frames_past_the_cap_are_refused_while_reading_counted_and_said(tmp_path, capsys):
    # a new frame in every message: every layout and a column per edge had been kept
    # before the cap applied (about 4 KB a transform), and the frames past it dropped silently
    import tracemalloc
    from dq_fk_ros.cli import dq_fk_bag
    cap = 500

    def read(count):
        path = tf_bag_of(tmp_path / f'frames_{count}', [
            (T0 + k * MS, [('world', f'frame_{k}', T0 + k * MS, (k, 0, 0, 0, 0, 0, 1))])
            for k in range(count)])
        tracemalloc.start()
        try:
            core, summary = core_from_bag(path, max_frames=cap)
            return core, summary, tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
    _, _, peak_small = read(1500)
    core, summary, peak = read(3000)
    count, held = 3000, cap - 1   # (world is a name too)
    assert len(core.frame_names()) == cap
    assert summary.transforms == held and summary.past_frame_cap == count - held
    assert summary.refused == count - held
    # what grows with the transforms: about 4 KB each before; the layouts remembered are
    # bounded (MAX_LAYOUTS) and paid by both reads
    assert (peak - peak_small) / 1500 < 400, (peak, peak_small)
    assert core.lookup('world', f'frame_{held - 1}', 0)[0][0] == held - 1
    # the command says it in one line (the default cap: 10 000 frames)
    path = tf_bag_of(tmp_path / 'more', [
        (T0 + k * MS, [('world', f'f{k % 10_005}', T0 + k * MS, (k, 0, 0, 0, 0, 0, 1))])
        for k in range(10_010)])
    assert dq_fk_bag.main(['tf', str(path), 'world', 'f3', '--csv',
                           str(tmp_path / 'f.csv'), '--rate', '100']) == 0
    err = capsys.readouterr().err
    assert 'dropped: 6 transforms naming frames past the 10000-frame cap' in err
    assert err.count('\n') == 1


def test_rows_at_a_rate_are_written_in_blocks_and_times_out_of_range_are_one_line(
        tmp_path, capsys):
    # a 2-message bag at --rate 1e6 had asked for > 6 GiB at once (a MemoryError traceback)
    import tracemalloc
    from dq_fk_ros.bag.tf_export import export_tf
    from dq_fk_ros.cli import dq_fk_bag
    path = tf_bag_of(tmp_path / 'two', [
        (T0, [('world', 'base', T0, (0, 0, 0, 0, 0, 0, 1))]),
        (T0 + 2 * 10**9, [('world', 'base', T0 + 2 * 10**9, (2, 0, 0, 0, 0, 0, 1))])])
    tracemalloc.start()
    try:
        done = export_tf(path, 'world', 'base', tmp_path / 'rows.csv', rate_hz=1e6)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert done.rows == 2_000_001 and done.unanswered == 0 and done.dropped == ''
    assert peak < 64 << 20, peak   # the rows: 2 M of 8 + 56 bytes and their text (~230 MB)
    with open(tmp_path / 'rows.csv') as stream:
        lines = stream.readlines()
    assert len(lines) == 2_000_002 and lines[1].startswith(f'{T0},0.000000000,')
    assert lines[1_000_001].startswith(f'{T0 + 10**9},1.000000000,')
    for option, value in (('--start', '1e300'), ('--start', '2.5'), ('--end', '-1')):
        assert dq_fk_bag.main(['tf', str(path), 'world', 'base', '--csv',
                               str(tmp_path / f'x{value}.csv'), '--rate', '10', option,
                               value]) == 2
        err = capsys.readouterr().err
        assert err.count('\n') == 1 and 'Traceback' not in err, err
        assert not (tmp_path / f'x{value}.csv').exists()
    assert 'past the end' in dq_fk_bag_error(tmp_path, path, capsys, '--start', '1e300')
    # an end past the bag's is its end
    assert dq_fk_bag.main(['tf', str(path), 'world', 'base', '--csv', str(tmp_path / 'e.csv'),
                           '--rate', '10', '--end', '1e300']) == 0
    assert capsys.readouterr().out.startswith(f'{tmp_path / "e.csv"}: 21 poses')


def dq_fk_bag_error(tmp_path, path, capsys, option, value):
    from dq_fk_ros.cli import dq_fk_bag
    assert dq_fk_bag.main(['tf', str(path), 'world', 'base', '--csv', str(tmp_path / 'y.csv'),
                           '--rate', '10', option, value]) == 2
    return capsys.readouterr().err
