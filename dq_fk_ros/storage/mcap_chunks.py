"""
An intact rosbag2 MCAP folder read a whole chunk at a time, without a Python object per record.

:class:`McapChunkReader` is the fast adapter of a rosbag2 folder whose MCAP files' summaries
pass their checks (:func:`~dq_fk_ros.storage.mcap_summary.read_summary`), opened without rosbags
(:func:`~dq_fk_ros.storage.mcap_folder.open_mcap_folder`) or, where that is not taken, by rosbags'
``Reader``. It walks the summary's chunk index, takes each
chunk whole (uncompressed: the bytes read; ``zstd``/``lz4``: decompressed within
its declared size, :mod:`dq_fk_ros.storage.decompress`), checks its CRC and finds its message
records with the compiled :func:`scan` (``_mcap.scan``; the reference :func:`scan_records`,
test_mcap_chunks.py holds them equal). Its :meth:`McapChunkReader.message_batches` hands
the messages on as :class:`MessageBatch` arrays: their bytes back to back in one buffer.

The order is rosbags' (the reference reader,
:class:`~dq_fk_ros.storage.rosbag2_reader.Rosbag2Reader`):
file by file; in a file, by log time, a tie going to the chunk that comes first in the file,
then to the record that comes first in the chunk (rosbags' heap merge of its chunks, each
sorted by log time). Chunks that do not overlap in time, holding their messages in time
order, are handed on in file order with no sorting; only where chunks overlap are their
messages merged. The same chunks are read as rosbags reads: those the message indexes say
hold a wanted channel, messages within the chunk's declared time span.

Anything the walk does not trust (a chunk record that is not where the index says, a
failed CRC, a record running past its chunk) raises :class:`ChunkDamaged`; ``dq_fk_bag
process`` then reads the bag again record by record (:meth:`McapChunkReader.fallback`), as
it does when rosbags stops in a damaged chunk. test_bag_readers.py holds this reader equal
to rosbags', message for message.
"""

import os
import struct
from typing import Iterator, Optional

from dq_fk_ros.kinematics.kernel import load_compiled
from dq_fk_ros.storage.crc import crc32
from dq_fk_ros.storage.decompress import ChunkRefused, decompress_chunk, MAX_CHUNK_BYTES
from dq_fk_ros.storage.mcap_format import OP_CHUNK
from dq_fk_ros.storage.mcap_summary import read_summary, SummaryRefused
from dq_fk_ros.storage.reader_interface import BagReader, BATCH, MessageBatch
import numpy as np

# as every extension: None without a C compiler at install, or with DQ_FK_PURE_PYTHON set
# (not empty, not 0)
COMPILED, _ = load_compiled('dq_fk_ros.storage._mcap')

_INT64_MIN, _INT64_MAX = -(1 << 63), (1 << 63) - 1
_CHUNK_HEAD = struct.Struct('<BQQQQI')   # opcode, length, start, end, size, crc
_RECORD = struct.Struct('<BQ')
_MESSAGE = struct.Struct('<HIQ')         # channel, sequence, log time


class ChunkDamaged(Exception):
    """A chunk this reader does not trust; the bag is to be read record by record."""


def scan_records(records, wanted, start, stop) -> tuple:
    """
    Return the wanted message records of a chunk: ``(times, offsets, lengths, channels)``.

    The reference of the compiled ``_mcap.scan`` (same arrays, same errors): messages whose
    channel ``c`` has ``wanted[c]`` and whose log time ``t`` has ``start <= t < stop``.
    Raises ``ValueError`` naming the byte where a record runs past the chunk.
    """
    found, pos, size = [], 0, len(records)
    while pos < size:
        if size - pos < 9:
            raise ValueError(f"the record at byte {pos} is cut off by the chunk's end")
        opcode, length = _RECORD.unpack_from(records, pos)
        if length > size - pos - 9:
            raise ValueError(f"the record at byte {pos} runs past the chunk's end")
        if opcode == 0x05:
            if length < 22:
                raise ValueError(f'the message record at byte {pos} is shorter than its header')
            channel, _, log_time = _MESSAGE.unpack_from(records, pos + 9)
            log_time -= (1 << 64) if log_time >> 63 else 0   # int64, as rosbags reads it
            if wanted[channel] and start <= log_time < stop:
                found.append((log_time, pos + 31, length - 22, channel))
        pos += 9 + length
    arrays = np.array(found, np.int64).reshape(-1, 4)
    return tuple(np.ascontiguousarray(arrays[:, k]) for k in range(4))


def _scan(records, wanted, start, stop):
    if COMPILED is None:
        return scan_records(records, wanted, start, stop)
    room = len(records) // 31 + 1
    out = [np.empty(room, np.int64) for _ in range(4)]
    n = COMPILED.scan(records, wanted, start, stop, *out)
    return tuple(a[:n] for a in out)


def _gather_into(buffer, offsets, lengths, out):
    """Copy the spans of ``buffer`` back to back to the start of ``out``."""
    if COMPILED is not None:
        COMPILED.gather(buffer, offsets, lengths, out)
        return
    view, at = memoryview(buffer), 0
    for o, n in zip(offsets.tolist(), lengths.tolist()):
        out[at:at + n] = view[o:o + n]
        at += n


class _Piece:
    """The wanted messages of one chunk, sorted, and the buffer they lie in."""

    __slots__ = ('buffer', 'times', 'offsets', 'lengths', 'ids', 'order_key')

    def __init__(self, buffer, times, offsets, lengths, ids, order_key):
        self.buffer, self.times, self.offsets = buffer, times, offsets
        self.lengths, self.ids, self.order_key = lengths, ids, order_key

    def take(self, which):
        """Return the piece of the messages ``which`` (an index array, a mask or a slice)."""
        return _Piece(self.buffer, self.times[which], self.offsets[which],
                      self.lengths[which], self.ids[which], self.order_key)

    def compact(self):
        """Return the same messages in a buffer of their own (the chunk's may then go)."""
        data = bytearray(int(self.lengths.sum()))
        _gather_into(self.buffer, self.offsets, self.lengths, memoryview(data))
        offsets = np.zeros(len(self.lengths), np.int64)
        np.cumsum(self.lengths[:-1], out=offsets[1:])
        return _Piece(bytes(data), self.times, offsets, self.lengths, self.ids,
                      self.order_key)


def _bounded(pieces):
    """
    Return ``pieces``, the messages of sparse ones copied out of their chunks' buffers.

    Pieces waiting for a batch to fill (or for later chunks' times) would hold every
    decompressed chunk they came from: thousands of chunks of one JointState each (the
    rest another topic's) held gigabytes. A piece whose buffer is more than twice its
    messages' bytes (and 4 KiB) keeps only its bytes: a copy that :func:`_cut` would make
    anyway; a dense piece (a JointState-only chunk) keeps its buffer, as before.
    """
    return [p if memoryview(p.buffer).nbytes <= 2 * int(p.lengths.sum()) + 4096
            else p.compact() for p in pieces]


class _FileChunks:
    """One MCAP file of the bag: its chunk index and its channels as connections."""

    def __init__(self, path, connections, summary=None):
        """Open ``path``; ``summary``: its :func:`~dq_fk_ros.storage.mcap_summary.read_summary`."""
        self.path = path
        if summary is None:
            try:
                summary = read_summary(path)
            except (OSError, SummaryRefused) as exc:
                raise ChunkDamaged(f'{path}: no summary to walk ({exc})') from None
        # chunks read with pread: memory stays one chunk whatever the file's length
        self.file = open(path, 'rb')
        self.size = os.fstat(self.file.fileno()).st_size
        self.chunks = [summary.chunk_index[k] for k in sorted(summary.chunk_index)]
        self.connection_of = {}     # channel id -> connection of the bag
        self.ids = np.full(65536, -1, np.int64)  # channel id -> the connection's id
        for channel in summary.channels.values():
            schema = summary.schemas.get(channel.schema_id)
            msgtype = schema.name if schema is not None else ''
            conn = next((c for c in connections
                         if (c.topic, c.msgtype) == (channel.topic, msgtype)), None)
            if conn is not None:
                self.connection_of[channel.id] = conn
                self.ids[channel.id] = conn.id

    def close(self):
        self.file.close()

    def channels_counted(self, chunk):
        """Channels whose message index in ``chunk`` holds a message (as rosbags counts)."""
        offsets = sorted((at, cid) for cid, at in chunk.message_index_offsets.items())
        ends = [at for at, _ in offsets[1:]] + [
            chunk.chunk_start_offset + chunk.chunk_length + chunk.message_index_length]
        return {cid for (at, cid), end in zip(offsets, ends) if (end - at - 15) // 16}

    def records(self, chunk) -> object:
        """Return the chunk's records, checked against the index and its CRC."""
        at, length = chunk.chunk_start_offset, chunk.chunk_length
        if at < 0 or length < _CHUNK_HEAD.size or length > self.size - at:
            raise ChunkDamaged(f'{self.path}: the chunk index points past the file')
        if length > MAX_CHUNK_BYTES + 4096:  # (its records are bounded by the same limit)
            raise ChunkDamaged(f'{self.path}: the chunk at byte {at} has {length} bytes; '
                               f'chunks over {MAX_CHUNK_BYTES >> 20} MiB are not read whole')
        data = os.pread(self.file.fileno(), length, at)
        opcode, body_length, _, _, size, crc = _CHUNK_HEAD.unpack_from(data, 0)
        body = _CHUNK_HEAD.size + 4 + len(chunk.compression) + 8
        if len(data) != length or opcode != OP_CHUNK or body_length != length - 9 or \
                size != chunk.uncompressed_size or \
                data[_CHUNK_HEAD.size + 4:body - 8] != chunk.compression.encode() or \
                body + chunk.compressed_size != length:
            raise ChunkDamaged(f'{self.path}: the chunk at byte {at} is not what its index says')
        raw = memoryview(data)[body:]
        try:
            # uncompressed: the mapped bytes themselves, no copy
            records = raw if chunk.compression == '' and len(raw) == size else \
                decompress_chunk(raw, chunk.compression, size)
        except ChunkRefused as exc:
            raise ChunkDamaged(f'{self.path}: the chunk at byte {at}: {exc}') from None
        if crc and crc32(records) != crc:
            raise ChunkDamaged(f'{self.path}: the chunk at byte {at} fails its CRC')
        return records


class McapChunkReader:
    """
    A rosbag2 folder of intact MCAP files, read a chunk at a time (a ``BagReader``).

    :param reference: the folder's :class:`~dq_fk_ros.storage.mcap_folder.McapFolder` or
        :class:`~dq_fk_ros.storage.rosbag2_reader.Rosbag2Reader`,
        whose connections, times and fallback this reader takes.
    """

    note = None
    damage = None
    copies_messages = True
    windowable = True

    def __init__(self, reference, mcaps, summaries=None):
        """
        Open the files and read their chunk indexes; raises :class:`ChunkDamaged`.

        :param summaries: the files' summaries, already read (None: read here).
        """
        self._reference = reference
        self.connections = reference.connections
        self.all_topics = reference.all_topics
        self.start_time, self.end_time = reference.start_time, reference.end_time
        self._files = []
        try:
            for k, path in enumerate(mcaps):
                self._files.append(_FileChunks(path, self.connections,
                                               summaries[k] if summaries else None))
        except Exception:
            self.close()
            raise

    def fallback(self) -> Optional[BagReader]:
        """Return the record-by-record reader of the same files (damage skipped)."""
        return self._reference.fallback()

    def close(self) -> None:
        """Unmap the files and close the reference reader."""
        for f in self._files:
            f.close()
        self._files = []
        self._reference.close()

    def messages(self, connections=None, start=None, stop=None) -> Iterator[tuple]:
        """Yield ``(connection, log_time_ns, raw CDR bytes)`` in rosbags' order."""
        by_id = {c.id: c for c in self.connections}
        for batch in self.message_batches(connections, start, stop):
            data = memoryview(batch.data)
            for cid, t, s, n in zip(batch.connection_ids.tolist(), batch.log_times.tolist(),
                                    batch.starts.tolist(), batch.lengths.tolist()):
                yield by_id[cid], t, bytes(data[s:s + n])

    def message_batches(self, connections=None, start=None, stop=None,
                        size=BATCH) -> Iterator[MessageBatch]:
        """
        Yield the messages as :class:`MessageBatch` es of ``size`` (the last one fewer).

        :param connections: only these (default all); ``start``/``stop``: log times
            ``start <= t < stop`` ns.
        """
        wanted_ids = {c.id for c in (self.connections if connections is None else connections)}
        pending = []
        count = 0
        try:
            for piece in self._pieces(wanted_ids, start, stop):
                pending.append(piece)
                pending = _bounded(pending)
                count += len(piece.times)
                while count >= size:
                    batch, pending, count = _cut(pending, size)
                    yield batch
        except ChunkDamaged:  # what was read before the damage goes on first
            if count:
                yield _cut(pending, count)[0]
            raise
        if count:
            yield _cut(pending, count)[0]

    def _pieces(self, wanted_ids, start, stop):
        for f in self._files:
            wanted = bytearray(65536)
            for cid, conn in f.connection_of.items():
                if conn.id in wanted_ids:
                    wanted[cid] = 1
            wanted = bytes(wanted)
            ids = {cid for cid, conn in f.connection_of.items() if conn.id in wanted_ids}
            chunks = [c for c in f.chunks
                      if (start is None or start < c.message_end_time + 1)
                      and (stop is None or c.message_start_time < stop)
                      and f.channels_counted(c) & ids]
            yield from self._file_pieces(f, chunks, wanted, start, stop)

    def _file_pieces(self, f, chunks, wanted, start, stop):
        """Yield the chunks' messages in (log time, chunk offset, record) order."""
        chunks = sorted(chunks, key=lambda c: (c.message_start_time, c.chunk_start_offset))
        pool = []
        for k, chunk in enumerate(chunks):
            records = f.records(chunk)
            lo = chunk.message_start_time if start is None else start
            hi = chunk.message_end_time + 1 if stop is None else stop
            try:
                times, offsets, lengths, channels = _scan(
                    records, wanted, max(lo, _INT64_MIN), min(hi, _INT64_MAX))
            except ValueError as exc:
                raise ChunkDamaged(f'{f.path}: the chunk at byte {chunk.chunk_start_offset}: '
                                   f'{exc}') from None
            order = np.argsort(times, kind='stable') if len(times) > 1 and \
                (np.diff(times) < 0).any() else None
            piece = _Piece(records, times, offsets, lengths, f.ids[channels],
                           chunk.chunk_start_offset)
            pool.append(piece if order is None else piece.take(order))
            below = chunks[k + 1].message_start_time if k + 1 < len(chunks) else None
            ready, pool = _ready(pool, below)
            pool = _bounded(pool)
            yield from ready


def _ready(pool, below):
    """
    Split the pool: what may be handed on before a chunk starting at ``below`` is read.

    Messages with a log time below ``below`` (all, when None) go out in (time, chunk
    offset, record) order; the rest stay. One chunk whose times are below ``below`` goes
    out as it is.
    """
    if len(pool) == 1 and (below is None or not len(pool[0].times)
                           or pool[0].times[-1] < below):
        return pool, []
    times = np.concatenate([p.times for p in pool])
    keys = np.concatenate([np.full(len(p.times), p.order_key, np.int64) for p in pool])
    which = np.concatenate([np.full(len(p.times), i, np.int64) for i, p in enumerate(pool)])
    rank = np.concatenate([np.arange(len(p.times)) for p in pool])
    order = np.lexsort((rank, keys, times))
    go = order if below is None else order[times[order] < below]
    out = []
    # consecutive messages of one chunk go out as one piece
    if len(go):
        cuts = np.flatnonzero(np.diff(which[go])) + 1
        for part in np.split(go, cuts):
            out.append(pool[int(which[part[0]])].take(rank[part]))
    kept = []
    if below is not None:
        stay = times >= below
        for i, p in enumerate(pool):
            mine = stay[which == i]
            if mine.any():
                kept.append(p.take(mine))
    return out, kept


def _cut(pieces, size):
    """Return the first ``size`` messages of ``pieces`` as a batch, and what remains."""
    taken, rest, parts = 0, [], []
    for p in pieces:
        if taken == size:
            rest.append(p)
            continue
        k = min(size - taken, len(p.times))
        parts.append(p.take(slice(0, k)))
        taken += k
        if k < len(p.times):
            rest.append(p.take(slice(k, None)))
    lengths = np.concatenate([p.lengths for p in parts])
    starts = np.zeros(len(lengths), np.int64)
    np.cumsum(lengths[:-1], out=starts[1:])
    data = bytearray(int(lengths.sum()))
    for p, at in zip(parts, np.cumsum([0] + [int(p.lengths.sum()) for p in parts[:-1]])):
        _gather_into(p.buffer, p.offsets, p.lengths, memoryview(data)[at:])
    batch = MessageBatch(np.concatenate([p.ids for p in parts]),
                         np.concatenate([p.times for p in parts]), data, starts, lengths)
    return batch, rest, sum(len(p.times) for p in rest)


__all__ = ['ChunkDamaged', 'McapChunkReader', 'scan_records']
