"""
The message index records of an MCAP chunk (https://mcap.dev/spec): one a channel.

A record is a 15-byte head (opcode, length, channel id, bytes of pairs) and the channel's
``(log time, offset in the chunk's records)`` pairs, little-endian uint64. The MCAP writer
(:mod:`~dq_fk_ros.storage.mcap_writer`) writes them after each chunk; readers find a chunk's
channels through them. :func:`message_indexes` lays out any chunk's; :class:`UniformIndex`
a chunk of rows (every channel one message a row), once a layout, its times written per
chunk; test_bag_writer.py holds both to the ``mcap`` library's ``MessageIndex`` records.
:func:`mcap_chunk_counts` reads them back: where a bag may be cut for the fleet's workers.
"""

from dataclasses import dataclass
import os
import struct
from typing import Optional

from dq_fk_ros.storage.mcap_format import OP_MESSAGE_INDEX
from dq_fk_ros.storage.mcap_summary import read_summary, SummaryRefused
import numpy as np

_U16, _U32, _U64 = struct.Struct('<H'), struct.Struct('<I'), struct.Struct('<Q')


def _record(opcode, body):
    return bytes((opcode,)) + _U64.pack(len(body)) + body


def _heads(channel_ids, m):
    """Return k records of m pairs each as a ``(k, 15 + 16 m)`` uint8 block, heads filled."""
    k, size = len(channel_ids), 15 + 16 * m
    block = np.empty((k, size), np.uint8)
    block[:, 0] = OP_MESSAGE_INDEX
    block[:, 1:9] = np.frombuffer(_U64.pack(size - 9), np.uint8)
    block[:, 9:11] = np.array(channel_ids, '<u2').view(np.uint8).reshape(k, 2)
    block[:, 11:15] = np.frombuffer(_U32.pack(16 * m), np.uint8)
    return block


def message_indexes(index: dict, at: int) -> tuple:
    """
    Return the message index records of a chunk, one a channel, and where each starts.

    ``index``: channel id -> ``(log times, offsets in the chunk's records)``; ``at``: the
    file offset of the first record. Channels of one length (a batch's, the usual case)
    are laid out together with numpy: a record is a 15-byte head (opcode, length, channel
    id, bytes of pairs) and its ``(log time, offset)`` pairs, little-endian uint64.
    """
    lengths = {len(times) for times, _ in index.values()}
    if len(lengths) != 1:
        parts, offsets = [], []
        for cid, (times, positions) in index.items():
            pairs = np.empty((len(times), 2), '<u8')
            pairs[:, 0], pairs[:, 1] = times, positions
            offsets.append((cid, at + sum(map(len, parts))))
            parts.append(_record(OP_MESSAGE_INDEX, _U16.pack(cid) + _U32.pack(pairs.nbytes)
                                 + pairs.tobytes()))
        return b''.join(parts), offsets
    m = lengths.pop()
    k = len(index)
    block = _heads(list(index), m)
    size = block.shape[1]
    pairs = np.empty((k, m, 2), '<u8')
    for row, (times, positions) in enumerate(index.values()):
        pairs[row, :, 0], pairs[row, :, 1] = times, positions
    block[:, 15:] = pairs.view(np.uint8).reshape(k, 16 * m)
    return block.reshape(-1), [(cid, at + row * size) for row, cid in enumerate(index)]


class UniformIndex:
    """
    The message index records of a chunk of rows, laid out once and reused.

    What :func:`message_indexes` makes for ``{cid: (times, offsets[k] + arange(m) *
    row_bytes)}``, byte for byte (test_bag_writer.py), without a dict or a layout a chunk.
    """

    def __init__(self, channel_ids: tuple, offsets, row_bytes: int, m: int):
        """Lay out the k records of m messages each; only the times change between chunks."""
        self.channel_ids, self.m = channel_ids, m
        k = len(channel_ids)
        block = _heads(channel_ids, m)
        self.size = block.shape[1]
        pairs = np.empty((k, m, 2), '<u8')
        pairs[:, :, 1] = np.asarray(offsets, np.int64)[:, None] + \
            np.arange(m, dtype=np.int64) * row_bytes
        block[:, 15:] = pairs.view(np.uint8).reshape(k, 16 * m)
        self.block = block
        self._times = block[:, 15:].view('<u8').reshape(k, m, 2)[:, :, 0]

    def set_times(self, times) -> None:
        """Write the chunk's log times (ns) into every channel's record."""
        self._times[:] = times

    def records(self, at: int) -> tuple:
        """Return the bytes (1-D uint8) and where each record starts, the first at ``at``."""
        return (self.block.reshape(-1),
                [(cid, at + row * self.size) for row, cid in enumerate(self.channel_ids)])


@dataclass(frozen=True)
class ChunkCounts:
    """
    Where a bag may be cut: its chunk start times and the topic's messages before each.

    ``starts``: sorted chunk start times (ns); ``before[i]``: messages of the topic with a
    log time before ``starts[i]``; ``total``: all of them.
    """

    starts: np.ndarray
    before: np.ndarray
    total: int

    def count_before(self, time_ns) -> int:
        """Return the messages before ``time_ns`` (a chunk start, or None: the bag's end)."""
        if time_ns is None:
            return self.total
        return int(self.before[np.searchsorted(self.starts, time_ns)])


def mcap_chunk_counts(files, topic) -> Optional[ChunkCounts]:
    """
    Return the :class:`ChunkCounts` of ``topic`` over MCAP ``files``, or None if not cut.

    Read from the summaries (:func:`~dq_fk_ros.storage.mcap_summary.read_summary`) and the
    message indexes only (no message is decoded, one chunk's index in memory at a time);
    None when a file's summary is refused or has no chunk index, or a chunk holding the
    topic has no message index for it.
    """
    chunks = []  # (file, start time, the topic's message index offsets) of every chunk
    try:
        for name in files:
            summary = read_summary(name)
            if not summary.chunk_index:
                return None
            ids = {i for i, c in summary.channels.items() if c.topic == topic}
            for chunk in summary.chunk_index.values():
                if ids and not chunk.message_index_offsets:
                    return None  # written without message indexes
                offsets = [chunk.message_index_offsets[i] for i in ids
                           if i in chunk.message_index_offsets]
                if offsets:
                    chunks.append((name, chunk.message_start_time, offsets))
        starts = np.unique(np.array([c[1] for c in chunks], dtype=np.int64))
        before = np.zeros(len(starts), np.int64)
        total = 0
        for name, _, offsets in chunks:
            with open(name, 'rb') as stream:
                for at in offsets:
                    times = np.sort(_index_times(stream, at))
                    before += np.searchsorted(times, starts, side='left')
                    total += len(times)
    except (OSError, SummaryRefused, struct.error, ValueError):
        return None
    return ChunkCounts(starts, before, total)


def _index_times(stream, offset):
    """
    Return the log times of one MessageIndex record at ``offset``.

    A record that claims more bytes than the file holds after it is refused before any is
    read (a hostile index would otherwise ask for up to 4 GiB at once).
    """
    stream.seek(offset)
    head = stream.read(15)
    opcode, length, _, size = struct.unpack('<BQHI', head)
    if opcode != OP_MESSAGE_INDEX or size % 16 or size + 6 > length or \
            size > os.fstat(stream.fileno()).st_size - offset - 15:
        raise ValueError('not a message index')
    return np.frombuffer(stream.read(size), dtype='<u8')[0::2].astype(np.int64)


__all__ = ['ChunkCounts', 'mcap_chunk_counts', 'message_indexes', 'UniformIndex']
