"""
The registry of bag formats (storage/formats.py): the recipe of docs/architecture.md holds.

A format made here, in the test, from the recipe alone (one ``BagReader`` adapter, one
``BagFormat`` row): a JSON-lines file of joint states. Every tool then reads it: it is
found by a fleet's walk, opened by ``open_reader``, processed by ``process_bag`` into what
the same joint states give from an MCAP bag. The writers of the registry are
``BagWriter`` s, the window plan of an MCAP bag is the ``mcap`` library's counting.
"""

import dataclasses
import json
import os
import tracemalloc

from dq_fk_ros.bag.discover import find_bags
from dq_fk_ros.bag.process import process_bag
from dq_fk_ros.bag.windows import chunk_counts
from dq_fk_ros.errors import BagError
from dq_fk_ros.storage import formats, mcap_writer
from dq_fk_ros.storage.formats import BagFormat, FORMATS, open_bag_writer
from dq_fk_ros.storage.mcap_summary import read_summary
from dq_fk_ros.storage.reader_interface import BagReader, BatchesFromMessages, JOINT_STATE
from dq_fk_ros.storage.reading import open_reader
from dq_fk_ros.storage.rosbags_writer import RosbagsWriter
from dq_fk_ros.storage.writer_interface import BagWriter
from mcap.reader import make_reader
import numpy as np
import pytest
from rosbags.interfaces import Connection, ConnectionExtRosbag2
from test_bag import js_bytes, NAMES, String, T0, trajectory, TS, write_bag

RL15 = 'rl15'


class JsonLinesBag(BatchesFromMessages):
    """A ``.jsonl`` file, one joint state a line: ``{"t": ns, "position": [...]}``."""

    note = damage = None
    copies_messages = True
    windowable = False

    def __init__(self, path):
        with open(path, encoding='utf-8') as stream:
            self.rows = [json.loads(line) for line in stream if line.strip()]
        self.connections = [Connection(1, '/joint_states', JOINT_STATE, '', '', len(self.rows),
                                       ConnectionExtRosbag2('cdr', []), None)]
        self.all_topics = [('/joint_states', JOINT_STATE)]
        self.start_time = self.rows[0]['t']
        self.end_time = self.rows[-1]['t'] + 1

    def messages(self, connections=None, start=None, stop=None):
        for row in self.rows:
            if (start is None or row['t'] >= start) and (stop is None or row['t'] < stop):
                yield self.connections[0], row['t'], js_bytes(NAMES, row['position'], row['t'])

    def fallback(self):
        return None

    def close(self):
        pass


JSONL = BagFormat('jsonl', 'a JSON-lines file of joint states',
                  found=lambda path: path.endswith('.jsonl'),
                  matches=lambda path: os.path.isfile(path) and path.endswith('.jsonl'),
                  opener=lambda path, msgtype=JOINT_STATE: JsonLinesBag(path), suffix='.jsonl')


@pytest.fixture
def with_jsonl(monkeypatch):
    """Put the new row in the registry, before the catch-all rosbag2 row."""
    monkeypatch.setattr(formats, 'FORMATS', FORMATS[:-1] + (JSONL,) + FORMATS[-1:])


def test_a_format_made_from_the_recipe_is_found_opened_and_processed(tmp_path, with_jsonl):
    q = trajectory(40)
    stamps = [T0 + k * 10_000_000 for k in range(len(q))]
    (tmp_path / 'fleet' / 'site').mkdir(parents=True)
    with open(tmp_path / 'fleet' / 'site' / 'run.jsonl', 'w', encoding='utf-8') as stream:
        for t, row in zip(stamps, q):
            stream.write(json.dumps({'t': t, 'position': list(row)}) + '\n')
    write_bag(tmp_path / 'same', [(t, js_bytes(NAMES, row, t)) for t, row in zip(stamps, q)])
    # found by a fleet's walk, its output named without the extension
    assert [(b.name, os.path.basename(b.path)) for b in find_bags([tmp_path / 'fleet'])] == \
        [('site/run', 'run.jsonl')]
    reader = open_reader(tmp_path / 'fleet' / 'site' / 'run.jsonl')
    assert isinstance(reader, JsonLinesBag) and isinstance(reader, BagReader)
    assert chunk_counts(tmp_path / 'fleet' / 'site' / 'run.jsonl', '/joint_states') is None
    # processed as the same joint states in an MCAP bag are
    for name, path in (('new', tmp_path / 'fleet' / 'site' / 'run.jsonl'),
                       ('mcap', tmp_path / 'same')):
        summary = process_bag(path, tmp_path / f'out_{name}', RL15, progress=False,
                              csv_path=tmp_path / f'{name}.csv')
        assert summary.read == summary.written == len(q)
    assert (tmp_path / 'new.csv').read_bytes() == (tmp_path / 'mcap.csv').read_bytes()
    assert len((tmp_path / 'new.csv').read_text().splitlines()) == len(q) + 1


def test_the_writers_of_the_registry_are_bag_writers(tmp_path):
    storages = {name: make for f in FORMATS for name, make in f.writers.items()}
    assert sorted(storages) == ['mcap', 'sqlite3']
    for name in storages:
        writer = open_bag_writer(tmp_path / name, name)
        assert isinstance(writer, BagWriter)
        writer.abort()
    assert isinstance(RosbagsWriter(tmp_path / 'x'), BagWriter)
    with pytest.raises(BagError, match=r"^--storage 'parquet': one of mcap, sqlite3$"):
        open_bag_writer(tmp_path / 'p', 'parquet')
    assert not (tmp_path / 'p').exists()


def test_an_mcap_bag_is_cut_where_the_mcap_library_counts_its_messages(tmp_path, monkeypatch):
    """The window plan (our one summary reader) against the ``mcap`` library's reading."""
    monkeypatch.setattr(mcap_writer, 'CHUNK_BYTES', 4000)   # chunks of ~20 messages
    q = trajectory(300)
    stamps = [T0 + k * 1_000_000 for k in range(len(q))]
    writer = RosbagsWriter(tmp_path / 'bag', 'mcap')
    writer.open()
    conn = writer.add_connection('/joint_states', JOINT_STATE, typestore=TS)
    chat = writer.add_connection('/chatter', 'std_msgs/msg/String', typestore=TS)
    for t, row in zip(stamps, q):
        writer.write(conn, t, js_bytes(NAMES, row, t))
        writer.write(chat, t, bytes(TS.serialize_cdr(String(data='x'), 'std_msgs/msg/String')))
    writer.close()
    counts = chunk_counts(tmp_path / 'bag', '/joint_states')
    (file,) = (tmp_path / 'bag').glob('*.mcap')
    with open(file, 'rb') as stream:
        reader = make_reader(stream)
        starts = sorted({c.message_start_time for c in reader.get_summary().chunk_indexes})
        times = np.array([m.log_time for _, _, m in
                          reader.iter_messages(topics=['/joint_states'])])
    assert len(starts) > 3   # several chunks, so several places to cut
    assert counts.starts.tolist() == starts and counts.total == len(q)
    assert counts.before.tolist() == [int(np.sum(times < s)) for s in starts]
    assert chunk_counts(tmp_path / 'bag', '/no_such_topic').total == 0


def test_every_row_is_complete():
    for row in FORMATS:
        assert all(getattr(row, f.name) is not None for f in dataclasses.fields(row)
                   if f.name not in ('reference', 'chunk_counts')), row.name


def test_a_message_index_claiming_more_than_the_file_is_not_read(tmp_path, monkeypatch):
    """A hostile index record's size (4 GiB) is refused before a byte of it is read."""
    monkeypatch.setattr(mcap_writer, 'CHUNK_BYTES', 4000)
    writer = RosbagsWriter(tmp_path / 'bag', 'mcap')
    writer.open()
    conn = writer.add_connection('/joint_states', JOINT_STATE, typestore=TS)
    for k, row in enumerate(trajectory(100)):
        writer.write(conn, T0 + k, js_bytes(NAMES, row, T0 + k))
    writer.close()
    (file,) = (tmp_path / 'bag').glob('*.mcap')
    assert chunk_counts(tmp_path / 'bag', '/joint_states') is not None
    offset = min(o for c in read_summary(str(file)).chunk_index.values()
                 for o in c.message_index_offsets.values())
    data = bytearray(file.read_bytes())
    data[offset + 1:offset + 9] = (1 << 62).to_bytes(8, 'little')       # record length
    data[offset + 11:offset + 15] = (0xFFFFFFF0).to_bytes(4, 'little')   # bytes of pairs
    file.write_bytes(bytes(data))
    tracemalloc.start()
    try:
        assert chunk_counts(tmp_path / 'bag', '/joint_states') is None
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 64 << 20, peak
