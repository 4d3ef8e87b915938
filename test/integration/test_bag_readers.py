"""
The bag reader interface: every format opens into an adapter that is a ``BagReader``.

The adapters are held equal to each other (rosbags' reader is the reference): the same
JointState bytes at the same log times, the same connections, start and end times, and
the same batches (``message_batches``) as messages.
"""

import shutil

from dq_fk_ros.bag.mcap_chunks import McapChunkReader
from dq_fk_ros.bag.mcap_stream import McapStreamBag
from dq_fk_ros.bag.reading import bag_format, BagReader, FORMATS, open_reader
from dq_fk_ros.bag.ros1_bag import Ros1Bag
from dq_fk_ros.bag.rosbag2_reader import Rosbag2Reader
from dq_fk_ros.errors import BagError
import pytest
from test_bag import valid_bag
from test_bag_hostile import write_ros1_bag


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
