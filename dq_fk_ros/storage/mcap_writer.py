"""
MCAP files of a rosbag2 folder, encoded a chunk at a time (https://mcap.dev/spec, ``ros2``).

:class:`McapChunkStorage` takes messages one at a time (``write``) or as whole arrays:
N messages on each of K connections, given as K ``(N, size)`` uint8 arrays of serialized
messages (:meth:`~McapChunkStorage.write_rows`; fixed size per connection, as
:class:`~dq_fk_ros.messages.cdr_templates.CdrTemplate` makes them), written interleaved in
time order.
:meth:`~McapChunkStorage.write_templates` serializes a batch of fixed-layout messages
straight into whole chunks in C (``_mcap.Rows``: message records from the templates and the
values); its reference is the numpy path of :meth:`~McapChunkStorage.write_rows`
(``CdrTemplate.fill`` and numpy records; test_mcap_chunks.py holds the two files equal byte
for byte). Every chunk has zlib's CRC-32 of its records and is uncompressed, or
``zstd``/``lz4`` when asked; the data section's CRC is left 0 (optional in the spec, and what
rosbag2's own MCAP writer leaves). The summary has schemas, channels, chunk indexes,
statistics and the ``rosbag2`` metadata record, as rosbag2's MCAP storage writes them.
Channels carry ``offered_qos_profiles`` and ``topic_type_hash``, which rosbag2 reads back.

It is the storage of both bag writers: :class:`~dq_fk_ros.storage.mcap_bag_writer.McapBagWriter`
(``dq_fk_bag process``, without rosbags' modules) and rosbags' ``Writer`` in
:class:`~dq_fk_ros.storage.rosbags_writer.RosbagsWriter` (the reference; its storage protocol:
``add_msgtype``, ``add_connection``, ``write``, ``close``, ``abort``).
"""

import os
import struct

from dq_fk_ros.kinematics.kernel import load_compiled
from dq_fk_ros.storage.crc import crc32
from dq_fk_ros.storage.mcap_format import (
    MAGIC, OP_CHANNEL, OP_CHUNK, OP_CHUNK_INDEX, OP_DATA_END, OP_FOOTER, OP_HEADER, OP_MESSAGE,
    OP_METADATA, OP_METADATA_INDEX, OP_SCHEMA, OP_STATISTICS, OP_SUMMARY_OFFSET)
from dq_fk_ros.storage.mcap_indexes import message_indexes, UniformIndex
import numpy as np
from rosbags.interfaces import MessageDefinitionFormat

# as every extension: None without a C compiler at install, or with DQ_FK_PURE_PYTHON set
# (not empty, not 0)
COMPILED, _ = load_compiled('dq_fk_ros.storage._mcap')

CHUNK_BYTES = 1 << 20          # close a chunk once its records exceed this (rosbags: 1 MiB)
RESERVE_BYTES = 64 << 20       # the file's blocks reserved ahead of the writes, at a time
COMPRESSIONS = ('none', 'zstd', 'lz4')   # dq_fk_bag process --compression

MESSAGE_HEADER_BYTES = 31      # opcode u8, length u64, channel u16, sequence u32, 2 x time u64
_U16, _U32, _U64 = struct.Struct('<H'), struct.Struct('<I'), struct.Struct('<Q')


def _library():
    from dq_fk_ros import __version__
    return f'dq_fk_ros-{__version__}'


def _string(text):
    data = text.encode('utf-8')
    return _U32.pack(len(data)) + data


def _string_map(pairs):
    body = b''.join(_string(k) + _string(v) for k, v in pairs)
    return _U32.pack(len(body)) + body


def _record(opcode, body):
    return bytes((opcode,)) + _U64.pack(len(body)) + body


class McapChunkStorage:
    """
    One MCAP file of a rosbag2 folder that also takes whole arrays of messages.

    rosbags' storage protocol (``add_msgtype``, ``add_connection``, ``write``, ``close``,
    ``abort``) plus :meth:`write_rows` and :meth:`write_templates`. Single messages collect
    in a pending chunk; a chunk closes at :data:`CHUNK_BYTES`, before rows are written, and
    at the end.
    """

    def __init__(self, path, compression=None, chunk_compression='none'):
        """
        Create ``<path>/<name>.mcap`` and write the magic and the header record.

        :param compression: rosbags' compression mode (``NONE`` or ``STORAGE``), or None.
        :param chunk_compression: ``none``, ``zstd`` or ``lz4``: how chunks are compressed.
        """
        if chunk_compression not in COMPRESSIONS:
            raise ValueError(f'chunk compression {chunk_compression!r}: one of '
                             f'{", ".join(COMPRESSIONS)}')
        if getattr(compression, 'name', 'NONE') not in ('NONE', 'STORAGE'):
            raise ValueError('the MCAP chunk storage compresses chunks, not files or messages')
        self.compression = '' if chunk_compression == 'none' else chunk_compression
        self.path = path / f'{path.name}.mcap'
        self.file = self.path.open('xb')
        self._rows_made = {}         # (channel ids, template ids) -> (_mcap.Rows, templates)
        self._block = np.empty(0, np.uint8)   # write_templates' chunk block, reused
        self._indexes_made = {}      # a chunk layout -> its UniformIndex
        self.schemas = []            # record bodies, for the summary
        self.schema_ids = {}         # msgtype -> schema id
        self.channels = []           # record bodies, for the summary
        self.chunk_indexes = []      # record bodies, for the summary
        self.channel_counts = {}     # channel id -> messages written
        self.start_ns, self.end_ns = None, None
        self._pending = bytearray()
        self._pending_index = {}     # channel id -> [(log time, offset)]
        self._reserved = 0           # the file's blocks reserved up to here
        self._can_reserve = True     # (False once the file system could not)
        self._emit(MAGIC)
        self._emit(_record(OP_HEADER, _string('ros2') + _string(_library())))

    def _emit(self, data):
        if self._can_reserve:
            end = self.file.tell() + len(data)
            if end > self._reserved:
                self._reserve(end)
        self.file.write(data)

    def _reserve(self, end):
        """
        Reserve the file's blocks up to ``end`` and beyond, its size kept (``_mcap.reserve``).

        Writing into reserved blocks skips the file system's reservation a page at a time
        (ext4: 456 MiB in 0.068 s instead of 0.095 on this machine); :meth:`_release` gives
        back what was not used. Where the file system cannot, it is not tried again.
        """
        start = self._reserved
        size = max(RESERVE_BYTES, end - start)
        if COMPILED is not None and COMPILED.reserve(self.file.fileno(), start, size):
            self._reserved = start + size
        else:
            self._can_reserve = False

    def _release(self):
        """Truncate the file to what was written: the reserved blocks past it are freed."""
        if self._reserved > 0:
            self.file.flush()
            os.ftruncate(self.file.fileno(), self.file.tell())

    def add_msgtype(self, connection) -> None:
        """Write the schema record of a message type (``ros2msg`` or ``ros2idl``)."""
        schema_id = len(self.schemas) + 1
        idl = connection.msgdef.format == MessageDefinitionFormat.IDL
        encoding = 'ros2idl' if idl else 'ros2msg'
        data = connection.msgdef.data.encode('utf-8')
        body = (_U16.pack(schema_id) + _string(connection.msgtype) + _string(encoding)
                + _U32.pack(len(data)) + data)
        self.schema_ids[connection.msgtype] = schema_id
        self.schemas.append(body)
        self._emit(_record(OP_SCHEMA, body))

    def add_connection(self, connection, offered_qos_profiles) -> None:
        """Write the channel record: topic, ``cdr``, QoS profiles and type hash metadata."""
        metadata = [('offered_qos_profiles', offered_qos_profiles)]
        if connection.digest:
            metadata.append(('topic_type_hash', connection.digest))
        body = (_U16.pack(connection.id) + _U16.pack(self.schema_ids[connection.msgtype])
                + _string(connection.topic) + _string(connection.ext.serialization_format)
                + _string_map(metadata))
        self.channels.append(body)
        self.channel_counts[connection.id] = 0
        self._emit(_record(OP_CHANNEL, body))

    def write(self, connection, timestamp, data) -> None:
        """Add one serialized message (log and publish time ``timestamp``) to the chunk."""
        offset = len(self._pending)
        self._pending += (bytes((OP_MESSAGE,)) + _U64.pack(22 + len(data))
                          + _U16.pack(connection.id) + _U32.pack(0)
                          + _U64.pack(timestamp) * 2)
        self._pending += data
        self._pending_index.setdefault(connection.id, []).append((timestamp, offset))
        if len(self._pending) > CHUNK_BYTES:
            self._close_pending()

    def write_rows(self, channel_ids, log_times_ns, payloads) -> None:
        """
        Write message i of every channel for every i, interleaved, in chunks.

        :param channel_ids: K channel (connection) ids.
        :param log_times_ns: ``(N,)`` int64, the log and publish time of message i.
        :param payloads: K ``(N, size_k)`` uint8 arrays of serialized messages.
        """
        self._close_pending()
        times = np.ascontiguousarray(log_times_ns, dtype='<u8')
        headers, sizes = [], []
        for cid, rows in zip(channel_ids, payloads):
            size = rows.shape[1]
            header = np.zeros(MESSAGE_HEADER_BYTES, np.uint8)
            header[:15] = np.frombuffer(bytes((OP_MESSAGE,)) + _U64.pack(22 + size)
                                        + _U16.pack(cid) + _U32.pack(0), np.uint8)
            headers.append(header)
            sizes.append(MESSAGE_HEADER_BYTES + size)
        row_bytes = sum(sizes)
        starts = np.cumsum([0] + sizes[:-1])
        per_chunk = max(1, CHUNK_BYTES // row_bytes)
        for lo in range(0, len(times), per_chunk):
            t = times[lo:lo + per_chunk]
            m = len(t)
            block = np.empty((m, row_bytes), np.uint8)
            index = {}
            for cid, rows, header, start, size in zip(channel_ids, payloads, headers, starts,
                                                      sizes):
                block[:, start:start + MESSAGE_HEADER_BYTES] = header
                stamps = block[:, start + 15:start + MESSAGE_HEADER_BYTES].view('<u8')
                stamps[:] = t[:, None]
                block[:, start + MESSAGE_HEADER_BYTES:start + size] = rows[lo:lo + m]
                index[cid] = (t, np.arange(m, dtype='<u8') * row_bytes + start)
            self._write_chunk(block, int(t.min()), int(t.max()), index)

    def write_templates(self, channel_ids, log_times_ns, stamps_ns, templates, values) -> None:
        """
        Write message i of every channel for every i from templates, in whole chunks.

        As :meth:`write_rows` of ``template.fill(stamps_ns, value)`` per channel; in C
        (``_mcap.Rows``) where it is built and every template's float runs have one width,
        no ``(N, size)`` array made per channel.

        :param templates: K :class:`~dq_fk_ros.messages.cdr_templates.CdrTemplate` s.
        :param values: K ``(N, floats of template k)`` float64 arrays (rows at any stride).
        """
        rows = self._rows(channel_ids, templates)
        if rows is None:
            self.write_rows(channel_ids, log_times_ns, [
                t.fill(stamps_ns, v) for t, v in zip(templates, values)])
            return
        self._close_pending()
        times = np.ascontiguousarray(log_times_ns, dtype=np.int64)
        stamps = np.ascontiguousarray(stamps_ns, dtype=np.int64)
        values = [np.asarray(v, dtype=np.float64) for v in values]
        row_bytes = rows.row_bytes
        per_chunk = max(1, CHUNK_BYTES // row_bytes)
        # one block for every chunk (each written out before the next), kept between calls
        need = min(len(times), per_chunk) * row_bytes
        if len(self._block) < need:
            self._block = np.empty(max(need, CHUNK_BYTES + row_bytes), np.uint8)
        whole = self._block
        ordered = len(times) < 2 or bool((times[1:] >= times[:-1]).all())  # (log time order)
        for lo in range(0, len(times), per_chunk):
            t = times[lo:lo + per_chunk]
            m = len(t)
            block = whole[:m * row_bytes]
            rows.fill(block, stamps[lo:lo + m], t, [v[lo:lo + m] for v in values])
            index = self._uniform_index(tuple(channel_ids), rows.offsets, row_bytes, t)
            self._write_chunk(block, int(t[0] if ordered else t.min()),
                              int(t[-1] if ordered else t.max()), index)

    def _uniform_index(self, channel_ids, offsets, row_bytes, times):
        """
        Return the message indexes of a chunk of rows (a :class:`UniformIndex`).

        Channel k's i-th message is at byte ``offsets[k] + i * row_bytes``, every channel at
        ``times``. The records, but for the times, are made once a layout (the last few kept).
        """
        key = (channel_ids, tuple(offsets), row_bytes, len(times))
        made = self._indexes_made.get(key)
        if made is None:
            if len(self._indexes_made) >= 4:
                self._indexes_made.clear()
            made = self._indexes_made[key] = UniformIndex(*key)
        made.set_times(times)
        return made

    def _rows(self, channel_ids, templates):
        """Return the compiled writer of these channels' templates (made once), or None."""
        if COMPILED is None:
            return None
        key = (tuple(channel_ids), tuple(map(id, templates)))
        made = self._rows_made.get(key)
        if made is None:
            widths = [{count for _, count in t.floats} for t in templates]
            rows = None
            if all(len(w) == 1 for w in widths):
                rows = COMPILED.Rows(channel_ids, [bytes(t.buf) for t in templates],
                                     [t.stamps for t in templates],
                                     [[at for at, _ in t.floats] for t in templates],
                                     [w.pop() for w in widths])
            made = self._rows_made[key] = (rows, templates)   # (the templates kept alive)
        return made[0]

    def _close_pending(self):
        if not self._pending:
            return
        index = {}
        for cid, entries in self._pending_index.items():
            pairs = np.array(entries, dtype='<u8').reshape(-1, 2)
            index[cid] = (pairs[:, 0], pairs[:, 1])
        times = np.concatenate([t for t, _ in index.values()])
        self._write_chunk(bytes(self._pending), int(times.min()), int(times.max()), index)
        self._pending = bytearray()
        self._pending_index = {}

    def _write_chunk(self, records, start_ns, end_ns, index):
        """Write a chunk record of ``records`` and a message index per channel."""
        records = memoryview(records).cast('B')
        size = len(records)
        chunk_start = self.file.tell()
        crc = crc32(records)
        stored = _compress(records, self.compression)
        head = (_U64.pack(start_ns) + _U64.pack(end_ns) + _U64.pack(size)
                + _U32.pack(crc) + _string(self.compression) + _U64.pack(len(stored)))
        self._emit(bytes((OP_CHUNK,)) + _U64.pack(len(head) + len(stored)) + head)
        self._emit(stored)
        index_start = self.file.tell()
        if isinstance(index, UniformIndex):
            records, offsets = index.records(index_start)
            for cid in index.channel_ids:
                self.channel_counts[cid] += index.m
        else:
            records, offsets = message_indexes(index, index_start)
            for cid, (times, _) in index.items():
                self.channel_counts[cid] += len(times)
        self._emit(records)
        offsets_map = b''.join(_U16.pack(cid) + _U64.pack(at) for cid, at in offsets)
        self.chunk_indexes.append(
            _U64.pack(start_ns) + _U64.pack(end_ns) + _U64.pack(chunk_start)
            + _U64.pack(index_start - chunk_start) + _U32.pack(len(offsets_map)) + offsets_map
            + _U64.pack(self.file.tell() - index_start) + _string(self.compression)
            + _U64.pack(len(stored)) + _U64.pack(size))
        self.start_ns = start_ns if self.start_ns is None else min(self.start_ns, start_ns)
        self.end_ns = end_ns if self.end_ns is None else max(self.end_ns, end_ns)

    def close(self, version, metadata) -> None:
        """Write the last chunk, the ``rosbag2`` metadata, the summary and the footer."""
        del version  # in the metadata text already
        self._close_pending()
        metadata_start = self.file.tell()
        self._emit(_record(OP_METADATA, _string('rosbag2')
                           + _string_map([('serialized_metadata', metadata)])))
        metadata_length = self.file.tell() - metadata_start
        self._emit(_record(OP_DATA_END, _U32.pack(0)))   # no data section CRC (optional)

        summary = bytearray()
        groups = []

        def group(opcode, bodies):
            if bodies:
                at = len(summary)
                for body in bodies:
                    summary.extend(_record(opcode, body))
                groups.append((opcode, at, len(summary) - at))
        counts = b''.join(_U16.pack(cid) + _U64.pack(n)
                          for cid, n in sorted(self.channel_counts.items()))
        statistics = (_U64.pack(sum(self.channel_counts.values()))
                      + _U16.pack(len(self.schemas)) + _U32.pack(len(self.channels))
                      + _U32.pack(0) + _U32.pack(1) + _U32.pack(len(self.chunk_indexes))
                      + _U64.pack(self.start_ns or 0) + _U64.pack(self.end_ns or 0)
                      + _U32.pack(len(counts)) + counts)
        group(OP_SCHEMA, self.schemas)
        group(OP_CHANNEL, self.channels)
        group(OP_CHUNK_INDEX, self.chunk_indexes)
        group(OP_METADATA_INDEX, [_U64.pack(metadata_start) + _U64.pack(metadata_length)
                                  + _string('rosbag2')])
        group(OP_STATISTICS, [statistics])
        summary_start = self.file.tell()
        offsets = b''.join(_record(OP_SUMMARY_OFFSET, bytes((opcode,))
                                   + _U64.pack(summary_start + at) + _U64.pack(length))
                           for opcode, at, length in groups)
        offsets_start = summary_start + len(summary)
        footer = (bytes((OP_FOOTER,)) + _U64.pack(20) + _U64.pack(summary_start)
                  + _U64.pack(offsets_start))
        crc = crc32(footer, crc32(offsets, crc32(summary)))
        self.file.write(bytes(summary) + offsets + footer + _U32.pack(crc) + MAGIC)
        self._release()
        self.file.close()

    def abort(self) -> None:
        """Close the file without a summary (an unfinished bag)."""
        try:
            self._release()
        finally:
            self.file.close()


class ArrayWrites:
    """
    N messages on each of K connections a call, for a writer with rosbags' ``Writer`` state.

    Needs ``storage`` (with ``write_rows``/``write_templates``), ``connections``, ``counts``,
    ``min_timestamp``, ``max_timestamp``; ``error`` is the class a misuse raises.
    """

    error = ValueError   # (each writer names its own: BagError, rosbags' WriterError)

    def write_rows(self, connections, log_times_ns, payloads) -> None:
        """
        Write N messages on each of K connections: message i of each has log time i.

        :param connections: K connections of this writer.
        :param log_times_ns: ``(N,)`` int64 nanoseconds.
        :param payloads: K ``(N, size_k)`` uint8 arrays, one serialized message a row.
        """
        if self.storage is None:
            raise self.error('Bag was not opened.')
        n = len(log_times_ns)
        self._check_rows(connections, n, payloads)
        if not n or not connections:
            return
        self.storage.write_rows([c.id for c in connections], log_times_ns, payloads)
        self._count(connections, log_times_ns)

    def write_templates(self, connections, log_times_ns, stamps_ns, templates, values) -> None:
        """
        Write N messages on each of K connections, serialized from their templates.

        As :meth:`write_rows` of ``templates[k].fill(stamps_ns, values[k])``; an MCAP bag
        writes them into its chunks in C, without those arrays.

        :param templates: K :class:`~dq_fk_ros.messages.cdr_templates.CdrTemplate` s.
        :param values: K ``(N, floats)`` float64 arrays.
        """
        if self.storage is None:
            raise self.error('Bag was not opened.')
        n = len(log_times_ns)
        self._check_rows(connections, n)
        if len(stamps_ns) != n or any(len(v) != n for v in values) or \
                len(templates) != len(connections) or len(values) != len(connections):
            raise ValueError(f'one template and one (N, floats) array a connection, N = {n}')
        if not n or not connections:
            return
        self.storage.write_templates([c.id for c in connections], log_times_ns, stamps_ns,
                                     templates, values)
        self._count(connections, log_times_ns)

    def abort(self) -> None:
        """Close the storage without a summary or metadata (a cut bag)."""
        storage, self.storage = self.storage, None
        if storage is not None:
            storage.abort()

    def _count(self, connections, log_times_ns):
        n = len(log_times_ns)
        for conn in connections:
            self.counts[conn.id] += n
        self.min_timestamp = min(self.min_timestamp, int(np.min(log_times_ns)))
        self.max_timestamp = max(self.max_timestamp, int(np.max(log_times_ns)))

    def _check_rows(self, connections, n, payloads=None):
        """Refuse connections this writer does not have, and payloads not ``(n, size)``."""
        for i, conn in enumerate(connections):
            if conn not in self.connections:
                raise self.error(f'Tried to write to unknown connection {conn!r}.')
            rows = None if payloads is None else payloads[i]
            if rows is not None and (rows.dtype != np.uint8 or rows.ndim != 2 or
                                     len(rows) != n):
                raise ValueError(f'payload of {conn.topic} must be ({n}, size) uint8, got '
                                 f'{rows.shape} {rows.dtype}')


def _compress(records, compression):
    """Return a chunk's records as stored: as they are, or compressed whole."""
    if not compression:
        return records
    if compression == 'zstd':
        try:
            from compression import zstd
        except ImportError:  # before Python 3.14: the backport (a dependency of rosbags)
            from backports import zstd
        return zstd.compress(records)
    import lz4.frame
    return lz4.frame.compress(records)
