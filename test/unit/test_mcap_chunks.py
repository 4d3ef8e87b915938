"""
MCAP chunks in C (``storage/_mcap.c``) against their references, and what the writer makes of them.

``_mcap.scan`` against :func:`~dq_fk_ros.storage.mcap_chunks.scan_records` on random record
streams (valid and broken); ``_mcap.gather`` against slicing; ``_mcap.Rows`` through
:meth:`RosbagsWriter.write_templates` against the numpy path (``CdrTemplate.fill`` and
``write_rows``): the two files are equal byte for byte. Compressed chunks read back in rosbags
and in the official ``mcap`` library with every CRC checked.
"""

import struct

from dq_fk_ros.messages.cdr_templates import pose_stamped_template, tf_message_template
from dq_fk_ros.storage import mcap_chunks, mcap_writer as bag_writer
from dq_fk_ros.storage.mcap_chunks import scan_records
from dq_fk_ros.storage.rosbags_writer import RosbagsWriter
from hypothesis import given, settings, strategies as st
from mcap.reader import make_reader
import numpy as np
import pytest
from rosbags.rosbag2 import Reader, WriterError
from rosbags.typesys import get_typestore, Stores

COMPILED = mcap_chunks.COMPILED
needs_c = pytest.mark.skipif(COMPILED is None, reason='the C extension _mcap is not built')
TS = get_typestore(Stores.ROS2_JAZZY)
T0 = 1_700_000_000_000_000_000


def message_record(channel, log_time, data, sequence=0):
    """Return an MCAP message record, written from the spec (not by the code under test)."""
    body = struct.pack('<HIQQ', channel, sequence, log_time % (1 << 64),
                       log_time % (1 << 64)) + data
    return struct.pack('<BQ', 0x05, len(body)) + body


def other_record(opcode, body):
    return struct.pack('<BQ', opcode, len(body)) + body


# log times and bounds from one small set (ties with the bounds) and the extremes
TIMES = st.one_of(st.integers(-3, 3), st.sampled_from([-2**63, 2**63 - 1, 2**62]))
records = st.lists(st.one_of(
    st.tuples(st.just('m'), st.integers(0, 5), TIMES, st.binary(max_size=40)),
    st.tuples(st.just('o'), st.integers(1, 255).filter(lambda op: op != 5),
              st.binary(max_size=30))), max_size=30)


def build(items):
    out = b''
    for item in items:
        out += message_record(*item[1:]) if item[0] == 'm' else other_record(*item[1:])
    return out


def compiled_scan(data, wanted, start, stop):
    room = len(data) // 31 + 1
    arrays = [np.full(room, -7, np.int64) for _ in range(4)]
    n = COMPILED.scan(data, wanted, start, stop, *arrays)
    return tuple(a[:n] for a in arrays)


def outcome(call, *args):
    try:
        return ('ok', [a.tolist() for a in call(*args)])
    except ValueError as exc:
        return ('error', str(exc))


@needs_c
@settings(max_examples=300, deadline=None)
@given(items=records, channels=st.sets(st.integers(0, 5)),
       bounds=st.tuples(TIMES, TIMES),
       cut=st.one_of(st.none(), st.integers(0, 2000)), flip=st.one_of(
           st.none(), st.tuples(st.integers(0, 2000), st.integers(1, 255))))
def test_the_compiled_scan_equals_the_reference(items, channels, bounds, cut, flip):
    data = bytearray(build(items))
    if flip is not None and data:
        data[flip[0] % len(data)] ^= flip[1]
    if cut is not None:
        data = data[:cut]
    wanted = bytearray(65536)
    for c in channels:
        wanted[c] = 1
    args = (bytes(data), bytes(wanted), *sorted(bounds))
    assert outcome(compiled_scan, *args) == outcome(scan_records, *args)


def test_the_reference_scan_finds_what_the_spec_says():
    data = (message_record(1, 10, b'abc') + other_record(0x07, b'x' * 5)
            + message_record(2, 20, b'') + message_record(1, -5, b'zz')
            + message_record(1, 30, b'q'))
    wanted = bytearray(65536)
    wanted[1] = 1
    times, offsets, lengths, channels = scan_records(data, bytes(wanted), 0, 30)
    assert times.tolist() == [10]          # -5 is before 0, 30 is not before 30
    assert data[offsets[0]:offsets[0] + lengths[0]] == b'abc'
    assert channels.tolist() == [1]
    with pytest.raises(ValueError, match="the record at byte 0 runs past the chunk's end"):
        scan_records(data[:20], bytes(wanted), 0, 100)
    short = struct.pack('<BQ', 0x05, 21) + bytes(21)
    with pytest.raises(ValueError, match='shorter than its header'):
        scan_records(short, bytes(wanted), 0, 100)


@needs_c
def test_the_compiled_scan_refuses_arrays_too_small_and_wrong_masks():
    data = message_record(0, 1, b'a') * 3
    small = [np.zeros(2, np.int64) for _ in range(4)]
    with pytest.raises(ValueError, match='more messages than the arrays hold'):
        COMPILED.scan(data, bytes([1]) + bytes(65535), 0, 10, *small)
    with pytest.raises(ValueError, match='65536 bytes'):
        COMPILED.scan(data, bytes(10), 0, 10, *small)
    with pytest.raises(ValueError, match='int64'):
        COMPILED.scan(data, bytes(65536), 0, 10, np.zeros(9, np.int32), *small[1:])


@needs_c
def test_gather_copies_the_spans_back_to_back_and_checks_them():
    src = bytes(range(100))
    offsets, lengths = np.array([5, 50, 0], np.int64), np.array([3, 0, 2], np.int64)
    dst = bytearray(6)
    assert COMPILED.gather(src, offsets, lengths, dst) == 5
    assert bytes(dst[:5]) == bytes([5, 6, 7, 0, 1])
    for bad in ([99], [-1], [2**62]):
        with pytest.raises(IndexError):
            COMPILED.gather(src, np.array(bad, np.int64), np.array([2], np.int64), dst)
    with pytest.raises(ValueError, match='do not fit'):
        COMPILED.gather(src, np.array([0], np.int64), np.array([7], np.int64), dst)


def write_outputs(path, n, compression='none', compiled=True, split=False):
    """Write a bag of N rows: /tf (2 edges) and /pose from templates, ragged stamps."""
    rng = np.random.default_rng(3)
    times = T0 + np.cumsum(rng.integers(0, 3_000_000, n)).astype(np.int64)
    stamps = times - rng.integers(-2 * 10**9, 2 * 10**9, n)   # some before, some after
    absolute = rng.normal(size=(n, 3, 7))
    relative = rng.normal(size=(n, 2, 7))
    saved = bag_writer.COMPILED
    bag_writer.COMPILED = saved if compiled else None
    try:
        writer = RosbagsWriter(path, 'mcap', compression)
        writer.open()
        tf = writer.add_connection('/tf', 'tf2_msgs/msg/TFMessage', typestore=TS)
        pose = writer.add_connection('/pose', 'geometry_msgs/msg/PoseStamped', typestore=TS)
        templates = [tf_message_template([('base', 'a'), ('a', 'bb')]),
                     pose_stamped_template('base')]
        # the pose's values: a strided view (frame 1 of 3), as BagOutputs hands them on
        parts = [slice(0, n)] if not split else [slice(0, n // 3), slice(n // 3, n)]
        for part in parts:
            writer.write_templates([tf, pose], times[part], stamps[part], templates,
                                   [relative[part].reshape(-1, 14), absolute[part, 1]])
        writer.close()
    finally:
        bag_writer.COMPILED = saved
    return times, stamps, absolute, relative


@needs_c
@pytest.mark.parametrize('split', [False, True])
def test_rows_in_c_write_the_file_the_numpy_path_writes(tmp_path, split):
    n = 9000   # several chunks
    for kind in ('c', 'numpy'):   # the same bag name: the metadata names its file
        (tmp_path / kind).mkdir()
        write_outputs(tmp_path / kind / 'out', n, compiled=kind == 'c', split=split)
    c = (tmp_path / 'c' / 'out' / 'out.mcap').read_bytes()
    reference = (tmp_path / 'numpy' / 'out' / 'out.mcap').read_bytes()
    assert len(c) > 9000 * 200
    assert c == reference


def decoded(path):
    """(topic, log time, stamp ns, floats) of every message, read by the mcap library."""
    out = []
    with open(next(path.glob('*.mcap')), 'rb') as f:
        for _, channel, message in make_reader(f, validate_crcs=True).iter_messages():
            msg = TS.deserialize_cdr(message.data, 'tf2_msgs/msg/TFMessage'
                                     if channel.topic == '/tf' else
                                     'geometry_msgs/msg/PoseStamped')
            if channel.topic == '/tf':
                heads = [t.header for t in msg.transforms]
                values = [v for t in msg.transforms for v in (
                    t.transform.translation.x, t.transform.translation.y,
                    t.transform.translation.z, t.transform.rotation.x, t.transform.rotation.y,
                    t.transform.rotation.z, t.transform.rotation.w)]
            else:
                heads = [msg.header]
                p = msg.pose
                values = [p.position.x, p.position.y, p.position.z, p.orientation.x,
                          p.orientation.y, p.orientation.z, p.orientation.w]
            stamps = {h.stamp.sec * 10**9 + h.stamp.nanosec for h in heads}
            assert len(stamps) == 1
            out.append((channel.topic, message.log_time, stamps.pop(), values))
    return out


@needs_c
@pytest.mark.parametrize('compression', ['none', 'zstd', 'lz4'])
def test_chunks_read_back_in_the_mcap_library_and_rosbags(tmp_path, compression):
    n = 5000   # two chunks
    times, stamps, absolute, relative = write_outputs(tmp_path / 'out', n, compression)
    got = decoded(tmp_path / 'out')
    expected = []
    for i in range(n):
        expected.append(('/tf', int(times[i]), int(stamps[i]), relative[i].ravel().tolist()))
        expected.append(('/pose', int(times[i]), int(stamps[i]), absolute[i, 1].tolist()))
    assert got == expected
    with Reader(tmp_path / 'out') as reader:
        assert reader.message_count == 2 * n
        assert [t for _, t, _ in reader.messages()] == [t for _, t, _, _ in expected]
    with open(next((tmp_path / 'out').glob('*.mcap')), 'rb') as f:
        summary = make_reader(f).get_summary()
    names = {index.compression for index in summary.chunk_indexes}
    assert names == {'' if compression == 'none' else compression}
    assert len(summary.chunk_indexes) >= 2


def test_a_compression_that_is_not_one_is_refused(tmp_path):
    with pytest.raises(WriterError, match="compression 'brotli': one of none, zstd, lz4"):
        RosbagsWriter(tmp_path / 'a', 'mcap', 'brotli')
    with pytest.raises(WriterError, match='sqlite3 bags are written uncompressed'):
        RosbagsWriter(tmp_path / 'b', 'sqlite3', 'zstd')


@needs_c
def test_rows_refuse_what_does_not_fit():
    rows = COMPILED.Rows([1, 2], [bytes(tf_message_template([('a', 'b')]).buf),
                                  bytes(pose_stamped_template('a').buf)],
                         [[8], [4]], [[28], [20]], [7, 7])
    n = 3
    out = np.zeros(n * rows.row_bytes, np.uint8)
    stamps = np.zeros(n, np.int64)
    good = [np.zeros((n, 7)), np.zeros((n, 7))]
    rows.fill(out, stamps, stamps, good)
    with pytest.raises(ValueError, match='out: 3 rows'):
        rows.fill(out[:-1], stamps, stamps, good)
    with pytest.raises(ValueError, match=r'values of channel 2: \(3, 7\)'):
        rows.fill(out, stamps, stamps, [good[0], np.zeros((n, 6))])
    with pytest.raises(ValueError, match='contiguous'):
        rows.fill(out, stamps, stamps, [good[0], np.zeros((n, 14))[:, ::2]])
    with pytest.raises(ValueError, match='one per channel'):
        rows.fill(out, stamps, stamps, good[:1])
    with pytest.raises(ValueError, match='slot offset'):
        COMPILED.Rows([1], [bytes(pose_stamped_template('a').buf)], [[4]], [[40]], [7])
    with pytest.raises(TypeError, match='set once'):
        rows.__init__([1], [b''], [[]], [[]], [1])


def test_the_fast_crc_is_zlibs():
    import zlib
    from dq_fk_ros.storage.crc import crc32
    rng = np.random.default_rng(5)
    for size in (0, 1, 7, 64, 1000, 1 << 20):
        data = rng.integers(0, 256, size, np.uint8).tobytes()
        assert crc32(data) == zlib.crc32(data)
        assert crc32(data, 12345) == zlib.crc32(data, 12345)
        assert crc32(memoryview(data)[1:]) == zlib.crc32(data[1:])
