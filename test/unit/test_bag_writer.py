"""
BagWriter: array writes read back by rosbags, and by the official MCAP library (Foxglove).

McapBagWriter (no rosbags module) writes the same bytes as RosbagsWriter (rosbags' Writer).

The MCAP checks use ``mcap`` (chunk and data-section CRCs validated, summary statistics) and
``mcap_ros2`` (decodes every message from the schema the bag carries): readers that share
no code with the writer.
"""

import struct
import zlib

from dq_fk_ros.errors import BagError
from dq_fk_ros.messages.cdr_templates import pose_stamped_template, tf_message_template
from dq_fk_ros.storage import mcap_indexes, mcap_writer as bag_writer
from dq_fk_ros.storage.mcap_bag_writer import McapBagWriter
from dq_fk_ros.storage.rosbags_writer import RosbagsWriter
from mcap.data_stream import RecordBuilder
from mcap.reader import make_reader
from mcap.records import Chunk, Message, MessageIndex
from mcap.stream_reader import StreamReader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
from rosbags.interfaces import (
    Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime)
from rosbags.rosbag2 import Reader, StoragePlugin, Writer, WriterError
from rosbags.typesys import get_typestore, Stores

TS = get_typestore(Stores.ROS2_JAZZY)
T0 = 1_700_000_000_000_000_000
EDGES = [('base', 'link_1'), ('link_1', 'link_2')]
NEVER = QosTime(sec=0, nsec=0)
LATCHED = [Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE,
               QosDurability.TRANSIENT_LOCAL, NEVER, NEVER, QosLiveliness.AUTOMATIC, NEVER,
               False)]


def content(n, seed=0):
    """N log times (1 kHz) and random pose / TF values."""
    rng = np.random.default_rng(seed)
    times = T0 + np.arange(n, dtype=np.int64) * 1_000_000
    return times, rng.normal(size=(n, 7)), rng.normal(size=(n, 14))


def sample_connections(writer):
    """Add /tf_static (latched), /pose and /tf to an open writer; return their connections."""
    return (writer.add_connection('/tf_static', 'tf2_msgs/msg/TFMessage', typestore=TS,
                                  offered_qos_profiles=LATCHED),
            writer.add_connection('/pose', 'geometry_msgs/msg/PoseStamped', typestore=TS),
            writer.add_connection('/tf', 'tf2_msgs/msg/TFMessage', typestore=TS))


def write_sample(path, storage, n, bulk=True):
    """
    One static message, then N (pose, tf) pairs; then a chatter message at the last time.

    ``bulk``: the pairs through :meth:`RosbagsWriter.write_rows`; otherwise one ``write`` each
    (rosbags' own storages when ``storage`` is a rosbags StoragePlugin).
    """
    times, pose_values, tf_values = content(n)
    poses = pose_stamped_template('base').fill(times, pose_values)
    tfs = tf_message_template(EDGES).fill(times, tf_values)
    if isinstance(storage, StoragePlugin):
        writer = Writer(path, version=9, storage_plugin=storage)
    else:
        writer = RosbagsWriter(path, storage)
    writer.open()
    static, pose, tf = sample_connections(writer)
    chat = writer.add_connection('/chatter', 'std_msgs/msg/String', typestore=TS)
    writer.write(static, int(times[0]), tfs[0].tobytes())
    if bulk:
        writer.write_rows([pose, tf], times, [poses, tfs])
    else:
        for i, t in enumerate(times.tolist()):
            writer.write(pose, t, poses[i].tobytes())
            writer.write(tf, t, tfs[i].tobytes())
    hello = TS.serialize_cdr(TS.types['std_msgs/msg/String'](data='hello'),
                             'std_msgs/msg/String')
    writer.write(chat, int(times[-1]), bytes(hello))
    writer.close()
    return times, pose_values, tf_values


def read_all(path):
    with Reader(path) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
        messages = [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]
        return messages, counts, qos, reader.duration


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_rows_read_back_like_rosbags_own_writer(tmp_path, storage):
    n = 6000  # about 2 MiB of records: several 1 MiB chunks
    write_sample(tmp_path / 'ours', storage, n)
    reference = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}[storage]
    write_sample(tmp_path / 'rosbags', reference, n, bulk=False)
    ours, reference = read_all(tmp_path / 'ours'), read_all(tmp_path / 'rosbags')
    assert ours[0] == reference[0]          # same messages, same order
    assert ours[1:] == reference[1:]        # counts, QoS, duration
    assert ours[1] == {'/tf_static': 1, '/pose': n, '/tf': n, '/chatter': 1}
    assert ours[2]['/tf_static'][0].durability == QosDurability.TRANSIENT_LOCAL


def test_single_writes_equal_row_writes(tmp_path):
    write_sample(tmp_path / 'rows', 'mcap', 700)
    write_sample(tmp_path / 'singles', 'mcap', 700, bulk=False)
    assert read_all(tmp_path / 'rows') == read_all(tmp_path / 'singles')


def test_mcap_reads_in_the_official_library_with_crcs_and_schemas(tmp_path, monkeypatch):
    monkeypatch.setattr(bag_writer, 'CHUNK_BYTES', 50_000)  # many chunks
    n = 2000
    times, pose_values, tf_values = write_sample(tmp_path / 'bag', 'mcap', n)
    path = tmp_path / 'bag' / 'bag.mcap'
    with open(path, 'rb') as f:  # every record; chunk and data-section CRCs checked
        records = list(StreamReader(f, validate_crcs=True, emit_chunks=True).records)
    chunks = [r for r in records if isinstance(r, Chunk)]
    assert len(chunks) > 10 and all(c.uncompressed_crc for c in chunks)
    with open(path, 'rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()], validate_crcs=True)
        summary = reader.get_summary()
        by_topic = {ch.topic: ch for ch in summary.channels.values()}
        assert summary.statistics.message_count == 2 * n + 2
        assert summary.statistics.channel_message_counts[by_topic['/pose'].id] == n
        assert len(summary.chunk_indexes) == len(chunks)
        assert summary.statistics.message_start_time == times[0]
        assert summary.statistics.message_end_time == times[-1]
        assert reader.get_header().profile == 'ros2'
        for topic, ch in by_topic.items():
            assert ch.message_encoding == 'cdr'
            assert ch.metadata['topic_type_hash'] == TS.hash_rihs01(
                summary.schemas[ch.schema_id].name)
            assert 'offered_qos_profiles' in ch.metadata
        assert 'transient_local' in by_topic['/tf_static'].metadata['offered_qos_profiles']
        pose_k = tf_k = 0
        for _, channel, message, decoded in reader.iter_decoded_messages(log_time_order=True):
            if channel.topic == '/pose':
                assert message.log_time == times[pose_k]
                p = decoded.pose
                assert [p.position.x, p.position.y, p.position.z, p.orientation.x,
                        p.orientation.y, p.orientation.z, p.orientation.w] == \
                    pose_values[pose_k].tolist()
                assert decoded.header.frame_id == 'base'
                pose_k += 1
            elif channel.topic == '/tf':
                second = decoded.transforms[1]
                assert (second.header.frame_id, second.child_frame_id) == EDGES[1]
                assert second.transform.rotation.w == tf_values[tf_k, 13]
                assert second.header.stamp.sec * 10**9 + second.header.stamp.nanosec == \
                    times[tf_k]
                tf_k += 1
        assert (pose_k, tf_k) == (n, n)
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        assert 'message_count: 4002' in metadata['rosbag2']['serialized_metadata']


def test_mcap_message_indexes_point_at_their_messages(tmp_path, monkeypatch):
    monkeypatch.setattr(bag_writer, 'CHUNK_BYTES', 20_000)
    write_sample(tmp_path / 'bag', 'mcap', 500)
    with open(tmp_path / 'bag' / 'bag.mcap', 'rb') as f:
        records = list(StreamReader(f, emit_chunks=True).records)
    checked = 0
    chunk = None
    for record in records:
        if isinstance(record, Chunk):
            chunk = record
        elif isinstance(record, MessageIndex):
            for log_time, offset in record.records:
                data = chunk.data
                assert data[offset] == 0x05  # a message record starts there
                channel, _, t = struct.unpack_from('<HIQ', data, offset + 9)
                assert (channel, t) == (record.channel_id, log_time)
                checked += 1
    assert checked == 1002
    assert not any(isinstance(r, Message) for r in records)  # every message is in a chunk


@pytest.mark.parametrize('lengths', [(3, 3, 3), (3, 1, 2), (0, 2)])
def test_message_index_records_are_the_mcap_librarys(lengths):
    """A chunk's message indexes, laid out together or one by one, as mcap's records."""
    rng = np.random.default_rng(len(lengths))
    index = {cid: (rng.integers(0, 2**63, m, dtype=np.int64), rng.integers(0, 2**40, m))
             for cid, m in zip((7, 2, 65535), lengths)}
    at = 1000
    records, offsets = mcap_indexes.message_indexes(index, at)
    expected, where = b'', []
    for cid, (times, positions) in index.items():
        where.append((cid, at + len(expected)))
        builder = RecordBuilder()
        MessageIndex(channel_id=cid, records=list(zip(times.tolist(), positions.tolist()))
                     ).write(builder)
        expected += builder.end()
    assert bytes(records) == expected and offsets == where


@pytest.mark.parametrize('k, m', [(1, 1), (3, 5), (8, 680)])
def test_a_reused_index_layout_is_the_one_made_afresh(k, m):
    """Hold UniformIndex (write_templates' chunks) to message_indexes, chunk after chunk."""
    rng = np.random.default_rng(k * m)
    cids = tuple(int(c) for c in rng.choice(65535, k, replace=False) + 1)
    offsets, row_bytes = np.sort(rng.integers(0, 200, k)), 200 + int(rng.integers(0, 100))
    uniform = mcap_indexes.UniformIndex(cids, offsets, row_bytes, m)
    for chunk in range(3):   # the same layout, other times
        times = rng.integers(0, 2**63, m, dtype=np.int64)
        uniform.set_times(times)
        steps = np.arange(m, dtype=np.int64) * row_bytes
        fresh = mcap_indexes.message_indexes(
            {cid: (times, steps + at) for cid, at in zip(cids, offsets)}, 5000 + chunk)
        got = uniform.records(5000 + chunk)
        assert bytes(got[0]) == bytes(fresh[0]) and got[1] == fresh[1]


def test_blocks_reserved_ahead_are_given_back(tmp_path, monkeypatch):
    """The file's blocks reserved ahead of the writes: the same bytes, none kept past the end."""
    if bag_writer.COMPILED is None:
        pytest.skip('the C extension _mcap is not built: nothing is reserved')
    calls = []
    reserve = bag_writer.COMPILED.reserve

    def spy(fd, offset, length):
        calls.append((offset, length))
        return reserve(fd, offset, length)
    monkeypatch.setattr(bag_writer, 'COMPILED', _Stand(bag_writer.COMPILED, reserve=spy))
    monkeypatch.setattr(bag_writer, 'RESERVE_BYTES', 1 << 19)
    (tmp_path / 'a').mkdir()
    (tmp_path / 'b').mkdir()
    write_sample(tmp_path / 'a' / 'bag', 'mcap', 6000)   # about 2 MiB: several reservations
    assert len(calls) >= 4 and calls[0][0] == 0
    assert all(b[0] == a[0] + a[1] for a, b in zip(calls, calls[1:]))  # each after the last
    monkeypatch.setattr(bag_writer, 'COMPILED', _Stand(bag_writer.COMPILED,
                                                       reserve=lambda *a: False))
    write_sample(tmp_path / 'b' / 'bag', 'mcap', 6000)
    reserved, plain = tmp_path / 'a' / 'bag' / 'bag.mcap', tmp_path / 'b' / 'bag' / 'bag.mcap'
    assert reserved.read_bytes() == plain.read_bytes()
    size = reserved.stat().st_size
    assert reserved.stat().st_blocks * 512 < size + (64 << 10)   # none of the last 512 KiB


def test_reserving_stops_once_the_file_system_refuses(tmp_path, monkeypatch):
    if bag_writer.COMPILED is None:
        pytest.skip('the C extension _mcap is not built: nothing is reserved')
    reserve, calls = bag_writer.COMPILED.reserve, []

    def once(fd, offset, length):   # the first works, then the disk is full, say
        calls.append(offset)
        return reserve(fd, offset, length) if len(calls) == 1 else False
    monkeypatch.setattr(bag_writer, 'COMPILED', _Stand(bag_writer.COMPILED, reserve=once))
    monkeypatch.setattr(bag_writer, 'RESERVE_BYTES', 1 << 19)
    write_sample(tmp_path / 'bag', 'mcap', 6000)
    path = tmp_path / 'bag' / 'bag.mcap'
    assert len(calls) == 2   # not tried again once refused
    assert path.stat().st_blocks * 512 < path.stat().st_size + (64 << 10)


def test_an_aborted_bag_keeps_no_reserved_blocks(tmp_path, monkeypatch):
    monkeypatch.setattr(bag_writer, 'RESERVE_BYTES', 8 << 20)
    writer = RosbagsWriter(tmp_path / 'cut', 'mcap')
    writer.open()
    tf = writer.add_connection('/tf', 'tf2_msgs/msg/TFMessage', typestore=TS)
    times, _, tf_values = content(300)
    writer.write_rows([tf], times, [tf_message_template(EDGES).fill(times, tf_values)])
    writer.storage.abort()
    path = tmp_path / 'cut' / 'cut.mcap'
    assert path.stat().st_blocks * 512 < path.stat().st_size + (1 << 20)


class _Stand:
    """A module's stand-in: its attributes, some replaced."""

    def __init__(self, module, **replaced):
        self._module, self._replaced = module, replaced

    def __getattr__(self, name):
        return self._replaced[name] if name in self._replaced else getattr(self._module, name)


def test_mcap_summary_crc(tmp_path):
    write_sample(tmp_path / 'bag', 'mcap', 50)
    data = (tmp_path / 'bag' / 'bag.mcap').read_bytes()
    footer = data[-8 - 29:-8]
    assert footer[0] == 0x02 and data[-8:] == b'\x89MCAP0\r\n'  # the spec's magic
    summary_start, _, crc = struct.unpack_from('<QQI', footer, 9)
    assert crc == zlib.crc32(data[summary_start:-8 - 4])


def test_an_empty_bag_is_valid(tmp_path):
    writer = RosbagsWriter(tmp_path / 'empty')
    writer.open()
    conn = writer.add_connection('/tf', 'tf2_msgs/msg/TFMessage', typestore=TS)
    writer.write_rows([conn], np.zeros(0, np.int64), [np.zeros((0, 40), np.uint8)])
    writer.close()
    messages, counts, _, _ = read_all(tmp_path / 'empty')
    assert messages == [] and counts == {'/tf': 0}
    with open(tmp_path / 'empty' / 'empty.mcap', 'rb') as f:
        assert make_reader(f).get_summary().statistics.message_count == 0


def test_write_rows_refuses_what_it_cannot_write(tmp_path):
    writer = RosbagsWriter(tmp_path / 'bag')
    rows = np.zeros((3, 8), np.uint8)
    with pytest.raises(WriterError, match='not opened'):
        writer.write_rows([], np.arange(3), [])
    writer.open()
    conn = writer.add_connection('/tf', 'tf2_msgs/msg/TFMessage', typestore=TS)
    other = RosbagsWriter(tmp_path / 'other')
    other.open()
    stranger = other.add_connection('/x', 'std_msgs/msg/String', typestore=TS)
    with pytest.raises(WriterError, match='unknown connection'):
        writer.write_rows([stranger], np.arange(3), [rows])
    with pytest.raises(ValueError, match=r'must be \(2, size\) uint8'):
        writer.write_rows([conn], np.arange(2), [rows])
    with pytest.raises(ValueError, match='uint8'):
        writer.write_rows([conn], np.arange(3), [rows.astype(float)])
    writer.close()
    other.close()


def write_both_ways(folder, make, compression, mode, n=3000):
    """Make the same calls on a writer: a latched topic, rows or templates or single writes."""
    times, pose_values, tf_values = content(n, seed=3)
    writer = make(folder, compression)
    writer.open()
    static, pose, tf = sample_connections(writer)
    templates = [pose_stamped_template('base'), tf_message_template(EDGES)]
    rows = [t.fill(times, v) for t, v in zip(templates, (pose_values, tf_values))]
    writer.write(static, int(times[0]), rows[1][0].tobytes())
    if mode == 'rows':
        writer.write_rows([pose, tf], times, rows)
    elif mode == 'templates':
        writer.write_templates([pose, tf], times, times, templates, [pose_values, tf_values])
    else:
        for i, t in enumerate(times.tolist()):
            writer.write(pose, t, rows[0][i].tobytes())
            writer.write(tf, t, rows[1][i].tobytes())
    writer.close()


@pytest.mark.parametrize('compression', ['none', 'zstd', 'lz4'])
@pytest.mark.parametrize('mode', ['rows', 'templates', 'singles'])
def test_the_bag_without_rosbags_is_byte_for_byte_rosbags_writers(tmp_path, compression, mode):
    """Hold McapBagWriter (dq_fk_bag process's MCAP output) to RosbagsWriter (rosbags' Writer)."""
    write_both_ways(tmp_path / 'ours' / 'bag', McapBagWriter, compression, mode)
    write_both_ways(tmp_path / 'ref' / 'bag', lambda p, c: RosbagsWriter(p, 'mcap', c),
                    compression, mode)
    for name in ('bag.mcap', 'metadata.yaml'):
        ours = (tmp_path / 'ours' / 'bag' / name).read_bytes()
        assert ours == (tmp_path / 'ref' / 'bag' / name).read_bytes(), name
    assert b'transient_local' in ours


def test_the_writer_without_rosbags_refuses_as_rosbags_writer_does(tmp_path):
    with pytest.raises(BagError, match="compression 'brotli': one of none, zstd, lz4"):
        McapBagWriter(tmp_path / 'a', 'brotli')
    (tmp_path / 'there').mkdir()
    with pytest.raises(BagError, match='exists already'):
        McapBagWriter(tmp_path / 'there')
    writer = McapBagWriter(tmp_path / 'bag')
    with pytest.raises(BagError, match='not opened'):
        writer.write_rows([], np.arange(3), [])
    writer.open()
    conn = writer.add_connection('/tf', 'tf2_msgs/msg/TFMessage', typestore=TS)
    with pytest.raises(BagError, match='only be added once'):
        writer.add_connection('/tf', 'tf2_msgs/msg/TFMessage', typestore=TS)
    with pytest.raises(BagError, match='msgdef'):
        writer.add_connection('/x', 'std_msgs/msg/String')
    with pytest.raises(BagError, match='unknown connection'):
        writer.write(conn._replace(id=9), 0, b'')
    writer.abort()
    assert not (tmp_path / 'bag' / 'metadata.yaml').exists()
