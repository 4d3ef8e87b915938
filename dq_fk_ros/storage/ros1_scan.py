"""
A ROS 1 bag read chunk by chunk from its start, without its index.

rosbags reads a ROS 1 bag through the index at its end (``index_pos`` in the bag header):
a bag whose index is damaged, cut off or points nowhere opens with an error, or with
nothing, although every chunk before it is intact. :class:`Ros1ChunkScan` walks the records
in file order instead ([ROS bag format 2.0]: a record is ``header_len, header, data_len,
data``; a chunk holds connection and message records): connections come from the chunks
themselves, a damaged chunk is skipped and reported, and after a damaged record the scan
resynchronises on the next intact chunk. Chunks are decompressed within their declared
size (:func:`~dq_fk_ros.storage.decompress.decompress_chunk`).
"""

import mmap
import os
import re
import struct
from typing import Iterator

from dq_fk_ros.storage.decompress import ChunkRefused, decompress_chunk

OP_MESSAGE, OP_BAG_HEADER, OP_INDEX, OP_CHUNK, OP_CHUNK_INFO, OP_CONNECTION = \
    0x02, 0x03, 0x04, 0x05, 0x06, 0x07
MAGIC = b'#ROSBAG V2.0\n'
MAX_HEADER_BYTES = 1 << 20   # a record header (field names and short values) is far smaller
_U32 = struct.Struct('<I')
_CHUNK_OP = re.compile(re.escape(b'\x04\x00\x00\x00op=\x05'))


class _Damaged(Exception):
    """A record that cannot be read; the message says why in a few words."""


def _fields(buf, start, end):
    """Return a record header's fields ``{name: bytes}`` from ``buf[start:end]``."""
    fields, pos = {}, start
    while pos < end:
        if pos + 4 > end:
            raise _Damaged('a header field is cut off')
        (length,) = _U32.unpack_from(buf, pos)
        pos += 4
        if length > end - pos:
            raise _Damaged('a header field runs past its header')
        field = bytes(buf[pos:pos + length])
        pos += length
        name, eq, value = field.partition(b'=')
        if not eq:
            raise _Damaged('a header field has no "="')
        fields[name] = value
    return fields


def _record(buf, pos, end):
    """Return ``(fields, data_start, data_end, next)`` of the record at ``pos``."""
    if pos + 4 > end:
        raise _Damaged(f'the file ends inside a record at byte {pos}')
    (header_len,) = _U32.unpack_from(buf, pos)
    if header_len > MAX_HEADER_BYTES or pos + 4 + header_len + 4 > end:
        raise _Damaged(f'a record at byte {pos} has an impossible header length')
    fields = _fields(buf, pos + 4, pos + 4 + header_len)
    at = pos + 4 + header_len
    (data_len,) = _U32.unpack_from(buf, at)
    if at + 4 + data_len > end:
        raise _Damaged(f'the record at byte {pos} runs past the end of the file')
    if b'op' not in fields or len(fields[b'op']) != 1:
        raise _Damaged(f'the record at byte {pos} has no type')
    return fields, at + 4, at + 4 + data_len, at + 4 + data_len


def _u32(fields, name):
    value = fields.get(name, b'')
    if len(value) != 4:
        raise _Damaged(f'field {name.decode()} is not 4 bytes')
    return _U32.unpack(value)[0]


class Ros1ChunkScan:
    """
    The JointState messages of a ROS 1 bag, read chunk by chunk (no index needed).

    Offers what :class:`~dq_fk_ros.storage.ros1_bag.Ros1Bag` offers; messages are yielded as ROS 1
    bytes and converted by the caller (``convert``). Opening scans the file once.
    """

    def __init__(self, path, joint_state_type):
        """Scan ``path`` once: connections, message counts, first and last time, damage."""
        self.path = os.fspath(path)
        self._type = joint_state_type
        with open(self.path, 'rb') as f:
            size = os.fstat(f.fileno()).st_size
            self._data = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) if size else b''
        self.damage = None
        self._problems = []
        self._topics = {}   # connection id -> (topic, ROS 2 type name)
        counts, times = {}, []
        for conn, time_ns, _ in self._messages(scanning=True):
            counts[conn] = counts.get(conn, 0) + 1
            times.append(time_ns)
        self.all_topics = sorted(set(self._topics.values()))
        from rosbags.interfaces import Connection, ConnectionExtRosbag1
        self.connections = [
            Connection(conn, topic, msgtype, None, '', counts.get(conn, 0),
                       ConnectionExtRosbag1(None, 0), None)
            for conn, (topic, msgtype) in sorted(self._topics.items())
            if msgtype in (joint_state_type if isinstance(joint_state_type, tuple)
                           else (joint_state_type,))]
        self.start_time = min(times) if times else 0
        self.end_time = max(times) + 1 if times else 0
        if self._problems:
            self.damage = f'{self.path}: {len(self._problems)} damaged part(s) skipped: ' + \
                '; '.join(self._problems[:3]) + (' ...' if len(self._problems) > 3 else '')

    def fallback(self) -> None:
        """Nothing else to fall back to."""
        return None

    def close(self) -> None:
        """Unmap the file."""
        if isinstance(self._data, mmap.mmap):
            self._data.close()
        self._data = b''

    def raw_messages(self, connections=None) -> Iterator[tuple]:
        """Yield ``(connection, log_time_ns, ROS 1 bytes)`` of the given JointState topics."""
        wanted = {c.id: c for c in (self.connections if connections is None else connections)}
        for conn, time_ns, raw in self._messages(scanning=False):
            if conn in wanted:
                yield wanted[conn], time_ns, raw

    def _messages(self, scanning):
        """Yield ``(connection id, time_ns, data)`` of every message record in file order."""
        buf, end = memoryview(self._data), len(self._data)
        if bytes(buf[:len(MAGIC)]) != MAGIC:
            raise _Damaged('not a ROS 1 bag (no "#ROSBAG V2.0" line)')
        pos = len(MAGIC)
        while pos < end:
            try:
                fields, start, stop, pos = _record(buf, pos, end)
            except _Damaged as exc:
                if scanning:
                    self._problems.append(str(exc))
                pos = self._resync(pos + 1)
                if pos is None:
                    return
                continue
            op = fields[b'op'][0]
            if op == OP_CHUNK:
                try:
                    raw = decompress_chunk(
                        buf[start:stop], fields.get(b'compression', b'').decode('latin-1'),
                        _u32(fields, b'size'))
                    records = list(self._chunk_records(memoryview(raw)))
                except (_Damaged, ChunkRefused) as exc:
                    if scanning:
                        self._problems.append(f'the chunk at byte {start}: {exc}')
                    continue
                yield from records
            elif op == OP_CONNECTION:
                try:
                    self._connection(fields, buf[start:stop])
                except _Damaged as exc:
                    if scanning:
                        self._problems.append(f'the connection at byte {start}: {exc}')

    def _chunk_records(self, raw):
        """Yield the messages of a decompressed chunk (its connections are noted)."""
        pos, end = 0, len(raw)
        while pos < end:
            fields, start, stop, pos = _record(raw, pos, end)
            op = fields[b'op'][0]
            if op == OP_CONNECTION:
                self._connection(fields, raw[start:stop])
            elif op == OP_MESSAGE:
                time = fields.get(b'time', b'')
                if len(time) != 8:
                    raise _Damaged('a message has no time')
                sec, nsec = struct.unpack('<II', time)
                yield _u32(fields, b'conn'), sec * 1_000_000_000 + nsec, bytes(raw[start:stop])

    def _connection(self, fields, data):
        conn = _u32(fields, b'conn')
        details = _fields(data, 0, len(data))
        msgtype = details.get(b'type', b'').decode('utf-8', 'replace')
        package, _, name = msgtype.partition('/')
        topic = fields.get(b'topic', details.get(b'topic', b'')).decode('utf-8', 'replace')
        self._topics.setdefault(conn, (topic, f'{package}/msg/{name}' if name else msgtype))

    def _resync(self, start):
        """Return the position of the next chunk record that reads whole, or None."""
        buf, end = self._data, len(self._data)
        for match in _CHUNK_OP.finditer(buf, start):
            for at in range(max(start, match.start() - 64), match.start()):
                try:
                    fields, begin, stop, _ = _record(memoryview(buf), at, end)
                    if fields[b'op'][0] != OP_CHUNK:
                        continue
                    raw = decompress_chunk(
                        memoryview(buf)[begin:stop],
                        fields.get(b'compression', b'').decode('latin-1'),
                        _u32(fields, b'size'))
                    list(self._chunk_records(memoryview(raw)))
                    return at
                except (_Damaged, ChunkRefused, struct.error):
                    continue
        return None


__all__ = ['Ros1ChunkScan']
