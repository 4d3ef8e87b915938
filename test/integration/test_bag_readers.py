"""
The bag reader interface: every format opens into an adapter that is a ``BagReader``.

The adapters are held equal to each other (rosbags' reader is the reference): the same
JointState bytes at the same log times, the same connections, start and end times, and
the same batches (``message_batches``) as messages.
"""

import shutil

from dq_fk_ros.bag.process import process_bag
from dq_fk_ros.cli.dq_fk_bag import main as bag_main
from dq_fk_ros.errors import BagError
from dq_fk_ros.storage import mcap_writer as bag_writer
from dq_fk_ros.storage.mcap_chunks import McapChunkReader
from dq_fk_ros.storage.mcap_stream import McapStreamBag
from dq_fk_ros.storage.reading import bag_format, BagReader, FORMATS, open_reader
from dq_fk_ros.storage.ros1_bag import Ros1Bag
from dq_fk_ros.storage.rosbag2_reader import Rosbag2Reader
from dq_fk_ros.storage.rosbags_writer import RosbagsWriter
from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np
import pytest
from rosbags.rosbag2 import Reader
from test_bag import js_bytes, NAMES, String, T0, TS, valid_bag, write_bag
import test_bag_hostile
from test_bag_hostile import write_ros1_bag

small_mcap = test_bag_hostile.small_mcap   # a fixture of 240 joint states in ~12 chunks


def messages_of(reader, **span):
    conns = [c for c in reader.connections if c.msgtype == 'sensor_msgs/msg/JointState']
    return [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages(conns, **span)]


def batches_of(reader, size, **span):
    """Return the messages of ``message_batches``, batch by batch, as ``messages_of``."""
    by_id = {c.id: c for c in reader.connections}
    conns = [c for c in reader.connections if c.msgtype == 'sensor_msgs/msg/JointState']
    out = []
    for batch in reader.message_batches(conns, size=size, **span):
        assert 0 < len(batch) <= size
        out += [(by_id[int(cid)].topic, int(t), bytes(batch.raw(i)))
                for i, (cid, t) in enumerate(zip(batch.connection_ids, batch.log_times))]
    return out


def opened(path, reference=False):
    reader = open_reader(path, reference=reference)
    try:
        assert isinstance(reader, BagReader)
        messages = messages_of(reader)
        assert batches_of(reader, 7) == messages
        return (type(reader), bag_format(path).name, messages,
                [(c.topic, c.msgtype, c.msgcount) for c in reader.connections],
                reader.start_time, reader.end_time, reader.note, reader.damage,
                reader.copies_messages, reader.windowable)
    finally:
        reader.close()


def test_every_format_opens_into_its_adapter_and_they_read_the_same(tmp_path):
    _, stamps = valid_bag(tmp_path / 'mcap', n=500, extra_topic=True)
    valid_bag(tmp_path / 'sqlite3', n=500, storage='sqlite3', extra_topic=True)
    reference = opened(tmp_path / 'mcap', reference=True)
    assert reference[:2] == (Rosbag2Reader, 'rosbag2')
    assert [t for _, t, _ in reference[2]] == stamps
    assert reference[3] == [('/joint_states', 'sensor_msgs/msg/JointState', 500),
                            ('/chatter', 'std_msgs/msg/String', 500)]
    assert reference[4:] == (stamps[0], stamps[-1] + 1, None, None, True, True)
    assert opened(tmp_path / 'sqlite3')[1:] == reference[1:]
    # an intact MCAP folder is read a chunk at a time, equal to rosbags' reading
    chunked = opened(tmp_path / 'mcap')
    assert chunked[0] == McapChunkReader and chunked[1:] == reference[1:]
    bare = next((tmp_path / 'mcap').glob('*.mcap'))
    shutil.copy(bare, tmp_path / 'bare.mcap')
    stream = opened(tmp_path / 'bare.mcap')
    # read record by record: no index, so the fleet cannot cut it into windows
    assert stream[:2] == (McapStreamBag, 'mcap')
    assert stream[2:6] == reference[2:6] and stream[6:] == (None, None, True, False)
    (tmp_path / 'mcap' / 'metadata.yaml').unlink()
    unfinished = opened(tmp_path / 'mcap')
    assert unfinished[0] == McapStreamBag and unfinished[2:4] == reference[2:4]
    assert 'not a complete rosbag2 (no metadata.yaml)' in unfinished[6]


def test_a_ros1_bag_opens_into_its_adapter(tmp_path):
    _, stamps = write_ros1_bag(tmp_path / 'in.bag', 50)
    kind, name, messages, conns, start, end, note, damage, copies, windows = \
        opened(tmp_path / 'in.bag')
    assert (kind, name) == (Ros1Bag, 'ros1')
    assert [t for _, t, _ in messages] == stamps and len(messages[0][2]) > 0
    assert conns == [('/joint_states', 'sensor_msgs/msg/JointState', 50)]
    assert (copies, windows, damage) == (False, False, None) and 'ROS 1 bag' in note


def test_the_registry_ends_with_rosbag2_and_refuses_what_no_format_reads(tmp_path):
    assert [f.name for f in FORMATS] == ['mcap', 'ros1', 'rosbag2']
    (tmp_path / 'notes.txt').write_text('hello')
    assert bag_format(tmp_path / 'notes.txt').name == 'rosbag2'  # the catch-all, which says
    with pytest.raises(BagError, match='notes.txt: not a readable rosbag2'):
        open_reader(tmp_path / 'notes.txt')
    with pytest.raises(BagError, match='no such bag'):
        open_reader(tmp_path / 'missing')
    # a file whose read fails (this process's memory at offset 0): one line naming it
    with pytest.raises(BagError, match=r'^/proc/self/mem: cannot be read \(Input/output error\)$'):
        open_reader('/proc/self/mem')


def test_a_time_span_is_read_alike_by_every_adapter(tmp_path):
    _, stamps = valid_bag(tmp_path / 'in', n=300)
    shutil.copy(next((tmp_path / 'in').glob('*.mcap')), tmp_path / 'bare.mcap')
    span = {'start': stamps[10], 'stop': stamps[20]}
    readers = [open_reader(tmp_path / 'in', reference=True), open_reader(tmp_path / 'in'),
               open_reader(tmp_path / 'bare.mcap')]
    try:
        got = [[t for _, t, _ in messages_of(r, **span)] for r in readers]
        assert [[t for _, t, _ in batches_of(r, 3, **span)] for r in readers] == got
    finally:
        for r in readers:
            r.close()
    assert got == [stamps[10:20]] * 3


def scrambled_bag(path, n, seed):
    """
    Write a rosbag2 MCAP whose chunks overlap in time, messages out of order, with ties.

    Written through RosbagsWriter's single writes with small chunks: log times go back and
    forth, some repeat (within a chunk and across chunks), two topics interleave.
    """
    rng = np.random.default_rng(seed)
    times = T0 + np.cumsum(rng.integers(-3, 6, n)) * 1_000_000
    times[rng.integers(0, n, n // 10)] = times[0]    # ties across chunks
    old = bag_writer.CHUNK_BYTES
    bag_writer.CHUNK_BYTES = 3000
    try:
        writer = RosbagsWriter(path, 'mcap')
        writer.open()
        joints = writer.add_connection('/joint_states', 'sensor_msgs/msg/JointState',
                                       typestore=TS)
        chatter = writer.add_connection('/chatter', 'std_msgs/msg/String', typestore=TS)
        for k, t in enumerate(times.tolist()):
            writer.write(joints, t, js_bytes(NAMES, [0.001 * k] * 6, T0 + k))
            if k % 3 == 0:
                writer.write(chatter, t, bytes(TS.serialize_cdr(
                    String(data=f'm{k}'), 'std_msgs/msg/String')))
        writer.close()
    finally:
        bag_writer.CHUNK_BYTES = old
    return times


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_chunks_that_overlap_are_read_in_rosbags_order(tmp_path, seed):
    times = scrambled_bag(tmp_path / 'in', 2000, seed)
    readers = [open_reader(tmp_path / 'in', reference=True), open_reader(tmp_path / 'in')]
    try:
        assert type(readers[1]) is McapChunkReader
        every = [[(c.topic, t, bytes(raw)) for c, t, raw in r.messages()] for r in readers]
        assert len(every[0]) == 2000 + 667 and every[1] == every[0]
        assert sorted(t for _, t, _ in every[0]) == [t for _, t, _ in every[0]]
        for size in (1, 5, 4096):
            assert batches_of(readers[1], size) == messages_of(readers[0])
        middle = int(np.median(times))
        span = {'start': middle - 5_000_000, 'stop': middle + 5_000_000}
        assert messages_of(readers[1], **span) == messages_of(readers[0], **span) != []
    finally:
        for r in readers:
            r.close()


def output_messages(path):
    with Reader(path) as reader:
        return [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]


@pytest.mark.parametrize('case', ['scrambled', 'split_publishers', 'copy_input'])
def test_processing_reads_alike_with_either_reader(tmp_path, case):
    if case == 'scrambled':
        scrambled_bag(tmp_path / 'in', 3000, 4)
    elif case == 'split_publishers':   # each message names half the joints
        stamps = [T0 + k * 10**7 for k in range(3000)]
        write_bag(tmp_path / 'in', [(s, js_bytes(NAMES[3 * (k % 2):3 * (k % 2) + 3],
                                                 [0.1 * (k % 7)] * 3, s))
                                    for k, s in enumerate(stamps)])
    else:
        valid_bag(tmp_path / 'in', n=3000, extra_topic=True)
    options = {'copy_input': case == 'copy_input', 'progress': False, 'chunk': 700}
    summaries = [process_bag(tmp_path / 'in', tmp_path / name, 'rl15', reference_reader=ref,
                             csv_path=tmp_path / f'{name}.csv', **options)
                 for name, ref in (('ref', True), ('chunks', False))]
    assert summaries[0].written > 0
    for s in summaries:
        s.output = None
    assert summaries[1] == summaries[0]
    assert output_messages(tmp_path / 'chunks') == output_messages(tmp_path / 'ref')
    assert (tmp_path / 'chunks.csv').read_text() == (tmp_path / 'ref.csv').read_text()


@settings(suppress_health_check=[HealthCheck.function_scoped_fixture], max_examples=40,
          deadline=None)
@given(flips=st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(1, 255)),
                      min_size=1, max_size=3))
def test_a_damaged_bag_reads_alike_with_either_reader(small_mcap, tmp_path_factory, capsys,
                                                      flips):
    """The same exit, lines and CSV: damage found in a chunk is read record by record."""
    folder, mcap, data, *_ = small_mcap
    damaged = bytearray(data)
    for where, xor in flips:
        damaged[int(where * len(data))] ^= xor
    work = tmp_path_factory.mktemp('case')
    (work / 'in').mkdir()
    (work / 'in' / 'metadata.yaml').write_bytes((folder / 'metadata.yaml').read_bytes())
    (work / 'in' / mcap.name).write_bytes(bytes(damaged))
    results = []
    for name, extra in (('ref', ['--reference-reader']), ('chunks', [])):
        rc = bag_main(['process', str(work / 'in'), str(work / name), '--robot', 'rl15',
                       '--csv', str(work / f'{name}.csv'), '--csv-only', '--quiet', *extra])
        out, err = capsys.readouterr()
        csv = (work / f'{name}.csv').read_text() if (work / f'{name}.csv').exists() else None
        results.append((rc, out.replace(str(work / name), 'OUT'), err, csv))
    assert results[1] == results[0]
