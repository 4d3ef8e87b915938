"""
A bag's TF as a :class:`~dq_fk_ros.transforms.buffer_core.BufferCore`: arrays per edge.

:func:`core_from_bag` reads ``/tf`` and ``/tf_static`` (``tf2_msgs/msg/TFMessage``) of a bag
of any format :func:`~dq_fk_ros.storage.reading.open_reader` opens (rosbag2 MCAP or sqlite3, a
bare ``.mcap``, ROS 1) through the :class:`~dq_fk_ros.storage.reader_interface.BagReader`
interface. ``/tf`` messages are read between ``start`` and ``end`` (log times, ns);
``/tf_static`` always whole (a static transform recorded at the start holds throughout).

Messages of one publisher share a layout (their frame ids): each layout is read once
(:func:`~dq_fk_ros.messages.cdr_tf.tf_layout`), and its messages' stamps and values are taken
as numpy columns at fixed offsets, no object per transform. Each edge's samples are sorted
by stamp, one sample a stamp (the first read; a later one of the same stamp is a duplicate,
or a repeated stamp refused as ``BufferCore.set_transform`` refuses it), and stored as the
core's arrays with no pruning (the whole bag is the cache). Transforms tf2 refuses (NaN or
infinite values, a quaternion off unit norm, a frame its own parent, an empty or too long
frame id) and frames past the core's cap are dropped and counted, the cap applied while
reading. The samples held are
bounded (``max_transforms``); a bag with more between ``start`` and ``end`` is refused in one
line that says to give them. Reference: the same transforms given one by one to
``BufferCore.set_transform`` (``test_tf_bag.py``).
"""

import os
import struct

from dq_fk_ros.errors import BagError, CdrError
from dq_fk_ros.messages.cdr_tf import LayoutCache, tf_layout
from dq_fk_ros.storage.reader_interface import TF_MESSAGE
from dq_fk_ros.storage.reading import open_reader
from dq_fk_ros.storage.text import printable
from dq_fk_ros.transforms.buffer_core import (BufferCore, MAX_FRAME_ID, MAX_FRAMES,
                                              QUATERNION_TOLERANCE, strip_slash)
from dq_fk_ros.transforms.edges import MovingEdge
import numpy as np

TF_TOPICS = ('/tf', '/tf_static')
TF_TYPES = (TF_MESSAGE, 'tf/msg/tfMessage')   # the second: older ROS 1 bags (tf's)
MAX_TRANSFORMS = 20_000_000   # samples held (80 bytes each while read: about 1.6 GB)
WHOLE_BAG_NS = 1 << 62        # the cache time of a bag's core: nothing pruned
MAX_LAYOUTS = 4096            # message layouts (publishers' frame-id sets) recognised at once


class TfBagSummary:
    """What :func:`core_from_bag` read: messages, transforms taken, dropped and why."""

    def __init__(self, max_frames: int = MAX_FRAMES):
        """Start at zero (``max_frames``: the frame cap the core was given)."""
        self.max_frames = max_frames
        self.messages = 0
        self.transforms = 0
        self.unreadable = 0      # messages that are no TFMessage
        self.refused = 0         # transforms refused (NaN, not unit, self, no frame id, ...)
        self.past_frame_cap = 0  # of them: naming frames past the core's cap (MAX_FRAMES)
        self.duplicates = 0      # a sample recorded twice, kept once
        self.repeated = 0        # another sample of a stamp its edge holds: refused

    def dropped_line(self) -> str:
        """Return one line saying what was dropped and why, or '' when nothing was."""
        parts = [f'{count} {what}' for count, what in (
            (self.past_frame_cap,
             f'transforms naming frames past the {self.max_frames}-frame cap'),
            (self.refused - self.past_frame_cap, 'transforms tf2 refuses (NaN, infinite, '
             'a quaternion off unit length, a frame its own parent, an empty or too long '
             'frame id)'),
            (self.repeated, "repeated stamps of an edge (tf2's TF_REPEATED_DATA)"),
            (self.unreadable, 'messages that are no TFMessage')) if count]
        return ('dropped: ' + '; '.join(parts)) if parts else ''


def core_from_bag(path, start: int | None = None, end: int | None = None,
                  max_transforms: int = MAX_TRANSFORMS, interpolation: str = 'slerp',
                  max_frames: int | None = None) -> tuple:
    """
    Return ``(BufferCore, TfBagSummary)`` of the bag's TF (module doc).

    :param start: the first log time (ns) of ``/tf`` read; ``end``: the first not read.
    :param max_frames: frame names held at most (default ``MAX_FRAMES``).
    :raises BagError: no TF topic, or more than ``max_transforms`` transforms (one line).
    """
    path = os.fspath(path)
    reader = open_reader(path, ros1_type=TF_MESSAGE)
    try:
        conns = [c for c in reader.connections
                 if c.msgtype in TF_TYPES and '/' + c.topic.lstrip('/') in TF_TOPICS]
        if not conns:
            topics = ', '.join(f'{printable(t)} ({printable(m)})'
                               for t, m in reader.all_topics[:20]) or 'none'
            raise BagError(f'{path} has no /tf or /tf_static ({TF_MESSAGE}); its topics: '
                           f'{topics}')
        core = BufferCore(WHOLE_BAG_NS, interpolation, max_frames or MAX_FRAMES)
        summary = TfBagSummary(core.max_frames)
        static = [c for c in conns if c.topic.lstrip('/') == 'tf_static']
        moving = [c for c in conns if c not in static]
        for conn, _, raw in reader.messages(static) if static else ():
            summary.messages += 1
            _take_static(core, raw, summary)
        if moving:
            _take_moving(core, reader, moving, start, end, max_transforms, summary, path)
        return core, summary
    finally:
        reader.close()


def _take_static(core, raw, summary):
    try:
        layout = tf_layout(bytes(raw))
    except CdrError:
        summary.unreadable += 1
        return
    for (parent, child), at in zip(layout.edges, layout.values):
        values = struct.unpack_from('<7d', layout.raw, at)
        if core.set_transform(parent, child, 0, values, 'bag', static=True):
            summary.transforms += 1
        else:
            summary.refused += 1


def _matches(known, data, starts, lengths):
    """Return a bool array: which messages (spans of ``data``) have ``known``'s layout."""
    if known.runs is not None:   # the compiled check, a memcmp per run
        return np.frombuffer(known.runs.match_many(data, starts, lengths, known.layout.size),
                             np.uint8).astype(bool)
    size = known.layout.size
    return np.array([n == size and known.match(data[s:s + n])
                     for s, n in zip(starts.tolist(), lengths.tolist())], bool)


class _Columns:
    """
    The transforms read so far, one row each, in arrays grown by half when full.

    Columns: stamp (int64 ns), read order (int64: the message's), parent and child id
    (int32), the 7 values (float64): 80 bytes a transform, whatever the bag's layouts.
    """

    def __init__(self):
        self.n = 0
        self.stamps = np.zeros(0, np.int64)
        self.orders = np.zeros(0, np.int64)
        self.ids = np.zeros((0, 2), np.int32)
        self.values = np.zeros((0, 7))

    def extend(self, stamps, orders, ids, values):
        """Append rows (equal lengths)."""
        n, more = self.n, len(stamps)
        if n + more > len(self.stamps):
            room = max(n + more, len(self.stamps) * 3 // 2, 1024)
            for name in ('stamps', 'orders', 'ids', 'values'):
                old = getattr(self, name)
                grown = np.zeros((room,) + old.shape[1:], old.dtype)
                grown[:n] = old[:n]
                setattr(self, name, grown)
        self.stamps[n:n + more] = stamps
        self.orders[n:n + more] = orders
        self.ids[n:n + more] = ids
        self.values[n:n + more] = values
        self.n = n + more


def _edge_ids(core, layout):
    """
    Return ``(ids, why)`` per transform of ``layout``: ``(parent id, child id)``, and why not.

    ``why`` is 0 (taken), 1 (a name tf2 refuses: empty, its own parent, longer than
    MAX_FRAME_ID) or 2 (a frame past the core's cap: refused here, while reading).
    """
    ids, why = [], []
    for parent, child in layout.edges:
        p, c = strip_slash(parent), strip_slash(child)
        if not p or not c or p == c or max(len(p), len(c)) > MAX_FRAME_ID:
            ids.append((0, 0))
            why.append(1)
            continue
        child_id = core.frame_index(c)
        parent_id = core.frame_index(p) if child_id else 0
        ids.append((parent_id, child_id) if parent_id else (0, 0))
        why.append(0 if parent_id else 2)
    return np.array(ids, np.int32).reshape(-1, 2), np.array(why, np.int8)


def _take_moving(core, reader, conns, start, end, max_transforms, summary, path):
    """
    Read ``/tf`` in batches, by layout, into columns; then store each edge sorted.

    Bounded while reading: at most ``max_transforms`` rows (then one line), frames past the
    core's cap refused and counted as they come, the layouts remembered at most
    ``MAX_LAYOUTS`` (each with its frame ids only), and a batch of messages whose layouts
    all differ read one message at a time rather than compared with each other.
    """
    columns = _Columns()
    known_layouts = LayoutCache(MAX_LAYOUTS)
    edge_ids = {}   # id(KnownLayout) -> (KnownLayout, ids per transform)
    order = 0
    for batch in reader.message_batches(conns, start, end):
        summary.messages += len(batch.starts)
        data = bytes(batch.data)
        block = np.frombuffer(data, np.uint8)
        left = np.arange(len(batch.starts))
        scans = 4 * len(left) + 64   # messages compared with a layout, at most, this batch
        while len(left):
            first = int(left[0])
            raw = data[batch.starts[first]:batch.starts[first] + batch.lengths[first]]
            try:
                known, forgotten = known_layouts.find(raw)
            except CdrError:
                summary.unreadable += 1
                left = left[1:]
                continue
            if forgotten is not None:
                edge_ids.pop(id(forgotten), None)
            entry = edge_ids.get(id(known))
            if entry is None or entry[0] is not known:
                entry = edge_ids[id(known)] = (known,) + _edge_ids(core, known.layout)
            _, ids, why = entry
            if scans >= len(left):
                scans -= len(left)
                same = _matches(known, data, batch.starts[left], batch.lengths[left])
                taken, left = left[same], left[~same]
            else:   # layouts that differ message after message: one at a time
                taken, left = left[:1], left[1:]
            layout = known.layout
            summary.refused += len(taken) * int((why != 0).sum())
            summary.past_frame_cap += len(taken) * int((why == 2).sum())
            kept = np.flatnonzero(why == 0)
            if not len(kept):
                continue
            if columns.n + len(taken) * len(kept) > max_transforms:
                raise BagError(f'{path}: more than {max_transforms} transforms on /tf between '
                               f'start and end (about {max_transforms * 80 >> 20} MiB held); '
                               'give start and end (--start/--end) to read a part of it')
            rows = block[batch.starts[taken][:, None] + np.arange(layout.size)]   # (n, size)
            stamps = np.stack([
                np.ascontiguousarray(rows[:, at:at + 4]).view('<i4')[:, 0].astype(np.int64)
                * 10**9 + np.ascontiguousarray(rows[:, at + 4:at + 8]).view('<u4')[:, 0]
                for at in (layout.stamps[j] for j in kept)], axis=1)
            values = np.stack([np.ascontiguousarray(rows[:, at:at + 56]).view('<f8')
                               for at in (layout.values[j] for j in kept)], axis=1)
            columns.extend(stamps.reshape(-1), np.repeat(order + taken, len(kept)),
                           np.tile(ids[kept], (len(taken), 1)), values.reshape(-1, 7))
        order += len(batch.starts)
    _store_all(core, columns, summary)


def _store_all(core, columns, summary):
    """Check the values as tf2 does, then store each child frame's samples sorted by stamp."""
    n = columns.n
    stamps, orders = columns.stamps[:n], columns.orders[:n]
    ids, values = columns.ids[:n], columns.values[:n]
    norm2 = np.einsum('ij,ij->i', values[:, 3:], values[:, 3:])
    good = np.isfinite(values).all(axis=1) & (np.abs(norm2 - 1.0) < QUATERNION_TOLERANCE)
    summary.refused += int((~good).sum())
    if not good.all():
        stamps, orders, ids, values, norm2 = (a[good] for a in (stamps, orders, ids, values,
                                                                norm2))
    values = values.copy()
    values[:, 3:] /= np.sqrt(norm2)[:, None]
    # by child, then stamp, then read order: of one stamp the first read is kept (a later
    # one the same in every value a duplicate, else a repeated stamp, tf2's TF_REPEATED_DATA)
    ordering = np.lexsort((orders, stamps, ids[:, 1]))
    stamps, ids, values = stamps[ordering], ids[ordering], values[ordering]
    bounds = np.flatnonzero(np.diff(ids[:, 1])) + 1
    for lo, hi in zip(np.r_[0, bounds], np.r_[bounds, len(stamps)]):
        if hi > lo:
            _store(core, int(ids[lo, 1]), stamps[lo:hi], ids[lo:hi, 0], values[lo:hi], summary)


def _store(core, child_id, stamps, parents, values, summary):
    """Store one child frame's samples (sorted by stamp, read order among equals)."""
    later = np.flatnonzero(stamps[1:] == stamps[:-1]) + 1
    if len(later):
        keep = np.ones(len(stamps), bool)
        keep[later] = False
        # the sample kept for each dropped one: the first of its stamp
        first = np.maximum.accumulate(np.where(keep, np.arange(len(stamps)), 0))[later]
        same = (parents[later] == parents[first]) & (values[later] == values[first]).all(axis=1)
        summary.duplicates += int(same.sum())
        summary.repeated += int((~same).sum())
        stamps, parents, values = stamps[keep], parents[keep], values[keep]
    core.caches[child_id] = MovingEdge.of(
        core.cache_time_ns, np.ascontiguousarray(stamps, np.int64).tobytes(),
        np.ascontiguousarray(parents, np.int64).tobytes(),
        np.ascontiguousarray(values, np.float64).tobytes())
    core.authority[child_id] = 'bag'
    summary.transforms += len(stamps)


__all__ = ['core_from_bag', 'MAX_TRANSFORMS', 'TF_TOPICS', 'TfBagSummary']
