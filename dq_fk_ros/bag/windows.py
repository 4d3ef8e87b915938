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
from typing import Optional

from dq_fk_ros.storage.formats import bag_format
from dq_fk_ros.storage.mcap_indexes import ChunkCounts
import numpy as np


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


def chunk_counts(path, topic) -> Optional[ChunkCounts]:
    """
    Return where the bag ``path`` may be cut (:class:`ChunkCounts` of ``topic``), or None.

    Its format's row says (:data:`~dq_fk_ros.storage.formats.FORMATS`' ``chunk_counts``):
    an MCAP bag from its summaries and message indexes; None for a bag never cut.
    """
    plan = bag_format(path).chunk_counts
    return plan(os.fspath(path), topic) if plan is not None else None


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


__all__ = ['chunk_counts', 'ChunkCounts', 'plan_windows', 'Window']
