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


def mcap_files(path):
    """Return the MCAP files of a bag (a rosbag2 folder's, split order; or the file)."""
    from dq_fk_ros.bag.reading import _mcap_files
    if os.path.isfile(path):
        return [path] if path.endswith('.mcap') else []
    return _mcap_files(path)


def joint_state_times(path, topic):
    """
    Return ``(sorted log times of topic's messages, sorted chunk start times)`` or None.

    Read from the MCAP summaries and message indexes only (no message is decoded); None
    when a file has no summary, no chunk index or no message index for the topic.
    """
    from mcap.exceptions import McapError
    from mcap.reader import make_reader
    files = mcap_files(path)
    if not files:
        return None
    times, starts = [], []
    for name in files:
        try:
            with open(name, 'rb') as stream:
                summary = make_reader(stream).get_summary()
                if summary is None or not summary.chunk_indexes:
                    return None
                ids = {i for i, c in summary.channels.items() if c.topic == topic}
                for chunk in summary.chunk_indexes:
                    offsets = [chunk.message_index_offsets[i] for i in ids
                               if i in chunk.message_index_offsets]
                    if ids and not chunk.message_index_offsets:
                        return None  # written without message indexes
                    found = [_index_times(stream, at) for at in offsets]
                    if found and sum(map(len, found)):
                        starts.append(chunk.message_start_time)
                    times += found
        except (OSError, McapError, struct.error, ValueError):
            return None
    all_times = np.sort(np.concatenate(times)) if times else np.zeros(0, np.int64)
    return all_times, np.unique(np.array(starts, dtype=np.int64))


def _index_times(stream, offset):
    """Return the log times of one MessageIndex record at ``offset``."""
    stream.seek(offset)
    head = stream.read(15)
    opcode, length, _, size = struct.unpack('<BQHI', head)
    if opcode != OP_MESSAGE_INDEX or size % 16 or size + 6 > length:
        raise ValueError('not a message index')
    records = np.frombuffer(stream.read(size), dtype='<u8').reshape(-1, 2)
    return records[:, 0].astype(np.int64)


def plan_windows(times, chunk_starts, count):
    """
    Cut a bag into at most ``count`` windows of about equal JointState counts.

    :param times: the sorted log times of the topic's messages; ``chunk_starts``: the
        sorted chunk start times (the only places a window may start).
    :returns: the :class:`Window` list (one window: the whole bag).
    """
    n = len(times)
    cuts = []
    for k in range(1, count):
        target = k * n / count
        before = np.searchsorted(times, chunk_starts, side='left')  # messages before each
        best = int(np.argmin(np.abs(before - target)))
        cut = int(chunk_starts[best])
        if 0 < before[best] < n and (not cuts or cut > cuts[-1]):
            cuts.append(cut)
    bounds = [None] + cuts + [None]
    windows = []
    for k in range(len(bounds) - 1):
        start = bounds[k]
        first = 0 if start is None else int(np.searchsorted(times, start, side='left'))
        earlier = [int(c) for c in chunk_starts if start is not None and c < start]
        lookback = []
        step = 1
        while step <= len(earlier):  # one chunk back, then two, four...
            lookback.append(earlier[-step])
            step *= 2
        windows.append(Window(k, len(bounds) - 1, start, bounds[k + 1], first,
                              tuple(lookback) + (None,)))
    return windows


__all__ = ['joint_state_times', 'mcap_files', 'plan_windows', 'Window']
