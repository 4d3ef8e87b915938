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
by stamp (stable: of equal stamps the later-read counts as the newer, as tf2 inserts them),
exact duplicates dropped, and stored as the core's arrays with no pruning (the whole bag is
the cache). Transforms tf2 refuses (NaN or infinite values, a quaternion off unit norm, a
frame its own parent, an empty frame id) are dropped and counted. The samples held are
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
from dq_fk_ros.transforms.buffer_core import BufferCore, QUATERNION_TOLERANCE, strip_slash
from dq_fk_ros.transforms.edges import MovingEdge
import numpy as np

TF_TOPICS = ('/tf', '/tf_static')
TF_TYPES = (TF_MESSAGE, 'tf/msg/tfMessage')   # the second: older ROS 1 bags (tf's)
MAX_TRANSFORMS = 20_000_000   # samples held (64 bytes each: about 1.3 GB)
WHOLE_BAG_NS = 1 << 62        # the cache time of a bag's core: nothing pruned
MAX_LAYOUTS = 4096            # message layouts (publishers' frame-id sets) recognised at once


class TfBagSummary:
    """What :func:`core_from_bag` read: messages, transforms taken, dropped and why."""

    def __init__(self):
        """Start at zero."""
        self.messages = 0
        self.transforms = 0
        self.unreadable = 0      # messages that are no TFMessage
        self.refused = 0         # transforms tf2 refuses (NaN, not unit, self, no frame id)
        self.duplicates = 0


def core_from_bag(path, start: int | None = None, end: int | None = None,
                  max_transforms: int = MAX_TRANSFORMS, interpolation: str = 'slerp'
                  ) -> tuple:
    """
    Return ``(BufferCore, TfBagSummary)`` of the bag's TF (module doc).

    :param start: the first log time (ns) of ``/tf`` read; ``end``: the first not read.
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
        core = BufferCore(WHOLE_BAG_NS, interpolation)
        summary = TfBagSummary()
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


def _take_moving(core, reader, conns, start, end, max_transforms, summary, path):
    """Read ``/tf`` in batches, by layout, into columns; then store each edge sorted."""
    layouts = []   # [KnownLayout] in the order first seen
    parts = {}     # id(KnownLayout) -> [(orders, stamps (n, T), values (n, T, 7))]
    known_layouts = LayoutCache(MAX_LAYOUTS)
    order = 0
    total = 0
    for batch in reader.message_batches(conns, start, end):
        summary.messages += len(batch.starts)
        data = bytes(batch.data)
        block = np.frombuffer(data, np.uint8)
        left = np.arange(len(batch.starts))
        while len(left):
            first = int(left[0])
            raw = data[batch.starts[first]:batch.starts[first] + batch.lengths[first]]
            try:
                known, _ = known_layouts.find(raw)
            except CdrError:
                summary.unreadable += 1
                left = left[1:]
                continue
            if id(known) not in parts:   # (a forgotten layout stays here, held by layouts)
                layouts.append(known)
                parts[id(known)] = []
            same = _matches(known, data, batch.starts[left], batch.lengths[left])
            taken = left[same]
            left = left[~same]
            total += len(taken) * len(known.layout.edges)
            if total > max_transforms:
                raise BagError(f'{path}: more than {max_transforms} transforms on /tf between '
                               f'start and end (about {max_transforms * 64 >> 20} MiB held); '
                               'give start and end (--start/--end) to read a part of it')
            layout = known.layout
            rows = block[batch.starts[taken][:, None] + np.arange(layout.size)]   # (n, size)
            stamps = np.stack([
                np.ascontiguousarray(rows[:, at:at + 4]).view('<i4')[:, 0].astype(np.int64)
                * 10**9 + np.ascontiguousarray(rows[:, at + 4:at + 8]).view('<u4')[:, 0]
                for at in layout.stamps], axis=1) if layout.edges else \
                np.zeros((len(taken), 0), np.int64)
            values = np.stack([np.ascontiguousarray(rows[:, at:at + 56]).view('<f8')
                               for at in layout.values], axis=1) if layout.edges else \
                np.zeros((len(taken), 0, 7))
            parts[id(known)].append((order + taken, stamps, values))
        order += len(batch.starts)
    columns = {}   # (parent, child) -> [(stamps, orders, values)]
    for known in layouts:
        if not parts[id(known)]:
            continue
        orders = np.concatenate([p[0] for p in parts[id(known)]])
        stamps = np.concatenate([p[1] for p in parts[id(known)]])
        values = np.concatenate([p[2] for p in parts[id(known)]])
        for j, (parent, child) in enumerate(known.layout.edges):
            columns.setdefault((parent, child), []).append(
                (stamps[:, j], orders, np.ascontiguousarray(values[:, j])))
    edges = {}   # child -> [(parent, stamps, orders, values)]
    for (parent, child), parts in columns.items():
        stamps = np.concatenate([p[0] for p in parts])
        orders = np.concatenate([p[1] for p in parts])
        values = np.concatenate([p[2] for p in parts])
        p, c = strip_slash(parent), strip_slash(child)
        if not p or not c or p == c:
            summary.refused += len(stamps)
            continue
        norm2 = np.einsum('ij,ij->i', values[:, 3:], values[:, 3:])
        good = np.isfinite(values).all(axis=1) & (np.abs(norm2 - 1.0) < QUATERNION_TOLERANCE)
        summary.refused += int((~good).sum())
        values = values[good]
        values[:, 3:] /= np.sqrt(norm2[good])[:, None]
        edges.setdefault(c, []).append((p, stamps[good], orders[good], values))
    for child, parts in edges.items():
        _store(core, child, parts, summary)


def _store(core, child, parts, summary):
    """Store one child frame's samples (of one or more parents) as its dynamic cache."""
    child_id = core.frame_index(child)
    if not child_id:
        summary.refused += sum(len(p[1]) for p in parts)
        return
    parents = np.concatenate([np.full(len(p[1]), core.frame_index(p[0]), np.int64) for p in parts])
    stamps = np.concatenate([p[1] for p in parts])
    orders = np.concatenate([p[2] for p in parts])
    values = np.concatenate([p[3] for p in parts])
    keep = parents != 0
    rows = np.concatenate((stamps[:, None].view(np.float64), parents[:, None].view(np.float64),
                           values), axis=1)[keep]
    orders = orders[keep]
    if len(orders) > 1 and not (orders[1:] > orders[:-1]).all():   # from several layouts
        ordering = np.argsort(orders, kind='stable')
        rows, orders = rows[ordering], orders[ordering]
    in_time = rows[:, 0].view(np.int64)
    if len(rows) > 1 and not (in_time[1:] > in_time[:-1]).all():
        # recorded out of order or twice: exact duplicates (stamp, parent, values) kept once
        # (the first read, as tf2 keeps it), then sorted by stamp, read order among equals
        _, first = np.unique(rows.view(np.dtype((np.void, rows.dtype.itemsize * 9))),
                             return_index=True)
        summary.duplicates += len(rows) - len(first)
        first.sort()
        rows, orders = rows[first], orders[first]
        rows = rows[np.lexsort((orders, rows[:, 0].view(np.int64)))]
    core.caches[child_id] = MovingEdge.of(
        core.cache_time_ns, np.ascontiguousarray(rows[:, 0]).view(np.int64).tobytes(),
        np.ascontiguousarray(rows[:, 1]).view(np.int64).tobytes(),
        np.ascontiguousarray(rows[:, 2:]).tobytes())
    core.authority[child_id] = 'bag'
    summary.transforms += len(rows)


__all__ = ['core_from_bag', 'MAX_TRANSFORMS', 'TF_TOPICS', 'TfBagSummary']
