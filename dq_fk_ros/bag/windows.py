"""
Cutting a large MCAP bag into windows that workers process side by side.

A window is the half-open span ``[start_ns, stop_ns)`` of log times between two chunk start
times (from the summary's chunk index; no message is in two windows). Its worker needs the
joint values the bag held at ``start_ns``: it first merges the messages of a look-back span
before it (one chunk, then two, four... back to the bag's start) until every joint has been
named, so its first /tf is what the one-bag run writes there: read in order (by log time,
as readers do), the windows' outputs are the one-bag run's, message for message.
``first_message`` counts the JointStates before the window (from the message indexes).

A bag without a usable summary, chunk index or message index is not cut (None): it is one
unit of work, processed as the one-bag command does.
"""

from dataclasses import dataclass
import os
import struct
from typing import Optional

import numpy as np

OP_MESSAGE_INDEX = 0x07


@dataclass(frozen=True)
class Window:
    """
    One window of a bag: messages with ``start_ns <= log time < stop_ns`` (None: open).

    ``first_message``: JointStates of the topic before ``start_ns``; ``lookback_ns``: where
    the look-back may start, nearest first (None last: the bag's start); ``index``, ``count``:
    which window of how many.
    """

    index: int
    count: int
    start_ns: int = None
    stop_ns: int = None
    first_message: int = 0
    lookback_ns: tuple = (None,)


def mcap_files(path) -> list:
    """Return the MCAP files of a bag (a rosbag2 folder's, split order; or the file)."""
    from dq_fk_ros.bag.reader_interface import mcap_folder_files
    if os.path.isfile(path):
        return [path] if path.endswith('.mcap') else []
    return mcap_folder_files(path)


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


def chunk_counts(path, topic) -> Optional[ChunkCounts]:
    """
    Return the :class:`ChunkCounts` of ``topic`` in an MCAP bag, or None if it cannot be cut.

    Read from the MCAP summaries and message indexes only (no message is decoded, one
    chunk's index in memory at a time); None when a file has no summary, no chunk index or
    no message index for the topic.
    """
    from mcap.exceptions import McapError
    from mcap.reader import make_reader
    files = mcap_files(path)
    if not files:
        return None
    chunks = []  # (start time, the topic's message index offsets) of every chunk
    try:
        for name in files:
            with open(name, 'rb') as stream:
                summary = make_reader(stream).get_summary()
            if summary is None or not summary.chunk_indexes:
                return None
            ids = {i for i, c in summary.channels.items() if c.topic == topic}
            for chunk in summary.chunk_indexes:
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
    except (OSError, McapError, struct.error, ValueError):
        return None
    return ChunkCounts(starts, before, total)


def _index_times(stream, offset):
    """Return the log times of one MessageIndex record at ``offset``."""
    stream.seek(offset)
    head = stream.read(15)
    opcode, length, _, size = struct.unpack('<BQHI', head)
    if opcode != OP_MESSAGE_INDEX or size % 16 or size + 6 > length:
        raise ValueError('not a message index')
    return np.frombuffer(stream.read(size), dtype='<u8')[0::2].astype(np.int64)


def plan_windows(counts, windows) -> list:
    """
    Cut a bag into at most ``windows`` windows of about equal message counts.

    :param counts: the bag's :class:`ChunkCounts` (windows start at chunk starts only).
    :returns: the :class:`Window` list (one window: the whole bag).
    """
    n, before, starts = counts.total, counts.before, counts.starts
    cuts = []
    for k in range(1, windows):
        best = int(np.argmin(np.abs(before - k * n / windows)))
        cut = int(starts[best])
        if 0 < before[best] < n and (not cuts or cut > cuts[-1]):
            cuts.append(cut)
    bounds = [None] + cuts + [None]
    out = []
    for k in range(len(bounds) - 1):
        start = bounds[k]
        earlier = [] if start is None else [int(c) for c in starts[starts < start]]
        lookback = []
        step = 1
        while step <= len(earlier):  # one chunk back, then two, four...
            lookback.append(earlier[-step])
            step *= 2
        out.append(Window(k, len(bounds) - 1, start, bounds[k + 1],
                          0 if start is None else counts.count_before(start),
                          tuple(lookback) + (None,)))
    return out


__all__ = ['chunk_counts', 'ChunkCounts', 'mcap_files', 'plan_windows', 'Window']
