"""
read_summary against the ``mcap`` library's reading of the same files; damage refused.

The library shares no code with it. Damage (bytes changed anywhere in the summary and
footer, the CRC switched off so that the records themselves are parsed) gives a summary or
:class:`SummaryRefused`, never another error.
"""

import struct

from dq_fk_ros.storage.mcap_summary import read_summary, SummaryRefused
from dq_fk_ros.storage.mcap_writer import McapChunkStorage
from hypothesis import given, HealthCheck, settings, strategies as st
from mcap.reader import make_reader
from mcap.writer import Writer as LibraryWriter
import pytest
from rosbags.interfaces import (
    Connection, ConnectionExtRosbag2, MessageDefinition, MessageDefinitionFormat)

T0 = 1_700_000_000_000_000_000


def ours(folder, compression='none', n=8000):
    """Write a file with McapChunkStorage: two channels of one schema, several chunks."""
    folder.mkdir()
    storage = McapChunkStorage(folder, None, compression)
    conns = [Connection(k, f'/topic_{k}', 'std_msgs/msg/String',
                        MessageDefinition(MessageDefinitionFormat.MSG, 'string data'), '', 0,
                        ConnectionExtRosbag2('cdr', []), None) for k in (1, 2)]
    storage.add_msgtype(conns[0])
    for conn in conns:
        storage.add_connection(conn, '[]')
    for i in range(n):
        storage.write(conns[i % 2], T0 + i, b'\x00\x01\x00\x00' + b'x' * 400)
    storage.close(9, 'version: 9')
    return storage.path


def library(path, profile='ros2'):
    """Write a file with the mcap library's writer (its chunking, metadata, attachments)."""
    with open(path, 'wb') as f:
        writer = LibraryWriter(f, chunk_size=2000)
        writer.start(profile=profile, library='test')
        schema = writer.register_schema('std_msgs/msg/String', 'ros2msg', b'string data')
        channels = [writer.register_channel(f'/t{k}', 'cdr', schema,
                                            {'offered_qos_profiles': '[]', 'k': str(k)})
                    for k in range(3)]
        for i in range(500):
            writer.add_message(channels[i % 3], T0 + i, b'\x00\x01\x00\x00hello', T0 + i)
        writer.add_metadata('rosbag2', {'serialized_metadata': 'x'})
        writer.add_attachment(T0, T0, 'a.txt', 'text/plain', b'attached')
        writer.finish()
    return path


def the_librarys(path):
    """Return the library's summary as the fields of read_summary's tuples."""
    with open(path, 'rb') as f:
        summary = make_reader(f).get_summary()
    return ({k: (s.id, s.name, s.encoding, bytes(s.data)) for k, s in summary.schemas.items()},
            {k: (c.id, c.schema_id, c.topic, c.message_encoding, dict(c.metadata))
             for k, c in summary.channels.items()},
            sorted((c.message_start_time, c.message_end_time, c.chunk_start_offset,
                    c.chunk_length, dict(c.message_index_offsets), c.message_index_length,
                    c.compression, c.compressed_size, c.uncompressed_size)
                   for c in summary.chunk_indexes))


def as_fields(summary):
    return ({k: tuple(s) for k, s in summary.schemas.items()},
            {k: tuple(c) for k, c in summary.channels.items()},
            sorted(tuple(c) for c in summary.chunk_index.values()))


@pytest.mark.parametrize('make', ['ours', 'ours-zstd', 'ours-lz4', 'library'])
def test_the_summary_is_the_librarys(tmp_path, make):
    path = library(tmp_path / 'lib.mcap') if make == 'library' else \
        ours(tmp_path / 'bag', make.partition('-')[2] or 'none')
    summary = read_summary(path)
    assert as_fields(summary) == the_librarys(path)
    assert len(summary.chunk_index) > 3 and summary.channels


def test_a_file_that_is_not_ros2_or_not_whole_is_refused(tmp_path):
    with pytest.raises(SummaryRefused, match='ros2'):
        read_summary(library(tmp_path / 'other.mcap', profile=''))
    data = library(tmp_path / 'lib.mcap').read_bytes()
    for name, damaged in (('cut', data[:-1]), ('empty', b''), ('magic', b'x' + data[1:]),
                          ('no summary', data[:-37] + b'\x02' + struct.pack('<QQQI', 20, 0, 0, 0)
                           + data[-8:]),
                          ('crc', data[:-20] + bytes([data[-20] ^ 1]) + data[-19:])):
        (tmp_path / name).write_bytes(damaged)
        with pytest.raises(SummaryRefused):
            read_summary(tmp_path / name)


def crc_off(data):
    """Return the same file, its summary CRC 0 (not checked): its records are then read."""
    return data[:-12] + b'\x00\x00\x00\x00' + data[-8:]


@pytest.fixture(scope='module')
def small_file(tmp_path_factory):
    """Return a library-written file, its summary CRC off, and where its summary starts."""
    data = crc_off(library(tmp_path_factory.mktemp('lib') / 'lib.mcap').read_bytes())
    return data, struct.unpack_from('<Q', data, len(data) - 28)[0]


@settings(suppress_health_check=[HealthCheck.function_scoped_fixture], max_examples=300,
          deadline=None)
@given(flips=st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(1, 255)),
                      min_size=1, max_size=4))
def test_damage_is_read_or_refused_never_an_error(small_file, tmp_path_factory, flips):
    data, start = small_file
    damaged = bytearray(data)
    for where, xor in flips:   # in the summary, its offsets and the footer
        damaged[start + int(where * (len(data) - start))] ^= xor
    path = tmp_path_factory.mktemp('case') / 'd.mcap'
    path.write_bytes(bytes(damaged))
    try:
        read_summary(path)
    except SummaryRefused:
        pass


def test_the_fuzzed_file_reads_whole_without_damage(small_file, tmp_path):
    """The fuzzing's file itself (CRC off) reads as the library reads it."""
    data, start = small_file
    (tmp_path / 'f.mcap').write_bytes(data)
    assert as_fields(read_summary(tmp_path / 'f.mcap')) == the_librarys(tmp_path / 'f.mcap')
    assert data[start] == 0x03   # the summary starts with the schema record


def test_a_summary_larger_than_the_bound_is_refused(tmp_path, monkeypatch):
    from dq_fk_ros.storage import mcap_summary
    path = library(tmp_path / 'lib.mcap')
    read_summary(path)
    monkeypatch.setattr(mcap_summary, 'MAX_SUMMARY_BYTES', 100)
    with pytest.raises(SummaryRefused, match='no summary'):
        read_summary(path)


def test_a_summary_of_more_channels_than_a_bag_is_read_with_is_refused(tmp_path, monkeypatch):
    """Each channel's QoS text is parsed: their number bounds the time (one line by the bag)."""
    from dq_fk_ros.storage import mcap_summary
    from dq_fk_ros.storage.mcap_folder import open_mcap_folder
    from dq_fk_ros.errors import BagError
    from test_rosbag2_metadata import write_bag
    path = write_bag(tmp_path / 'bag')   # three channels
    monkeypatch.setattr(mcap_summary, 'MAX_CHANNELS', 2)
    with pytest.raises(mcap_summary.SummaryTooLarge, match='more than 2 channels'):
        read_summary(path / 'bag.mcap')
    with pytest.raises(BagError, match=r'bag\.mcap: its summary lists more than 2 channels'):
        open_mcap_folder(str(path))
    monkeypatch.setattr(mcap_summary, 'MAX_CHANNELS', 3)
    open_mcap_folder(str(path)).close()   # (three: read)
