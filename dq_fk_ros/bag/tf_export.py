"""
``dq_fk_bag tf BAG TARGET SOURCE --csv FILE``: one frame's pose in another over a bag, as CSV.

The bag's TF is read into arrays (:func:`~dq_fk_ros.bag.tf_bag.core_from_bag`) and looked
up at many stamps at once (:func:`~dq_fk_ros.transforms.batch.lookup_poses`): every
``1 / rate`` seconds over the span of ``/tf`` (``--rate``), or at the header stamp of each
message of a topic (``--at-topic``, e.g. a camera's images: "the camera in the base frame at
this image's stamp"). Columns ``stamp_ns,x,y,z,qx,qy,qz,qw`` (metres; quaternion x y z w).
Stamps where TF cannot answer (before or after the data, frames not connected) are counted
and left out, never invented.
"""

import math
import os
import struct
from typing import Iterator, NamedTuple

from dq_fk_ros.bag.tf_bag import core_from_bag
from dq_fk_ros.errors import BagError
from dq_fk_ros.storage.reading import open_reader
from dq_fk_ros.storage.text import printable
from dq_fk_ros.transforms.batch import lookup_poses
from dq_fk_ros.transforms.buffer_core import COMPILED
import numpy as np

MAX_ROWS = 50_000_000   # stamps asked at most (--rate over a long bag)
CSV_ROWS_AT_ONCE = 65536
_STAMP = struct.Struct('<iI')


class TfExport(NamedTuple):
    """What :func:`export_tf` did: rows written, stamps TF could not answer, the CSV."""

    rows: int
    unanswered: int
    csv_path: str
    dropped: str = ''   # what the bag's TF held that was dropped, one line ('' for nothing)


def tf_span(core) -> tuple:
    """Return ``(first, last)`` stamp (ns) of the core's moving samples, or None without any."""
    first, last = None, None
    for cache in core.caches:
        if cache is not None and not cache.static and len(cache):
            a, b = cache.oldest_stamp(), cache.newest_stamp()
            first = a if first is None else min(first, a)
            last = b if last is None else max(last, b)
    return None if first is None else (first, last)


def stamps_at_rate(core, rate_hz: float, block: int = CSV_ROWS_AT_ONCE) -> Iterator[np.ndarray]:
    """
    Yield stamps every ``1 / rate_hz`` s over the span of the core's moving samples.

    ``block`` stamps at a time: what is held does not grow with the rows. More than
    ``MAX_ROWS`` in all: a one-line BagError before any is yielded.
    """
    span = tf_span(core)
    if span is None:
        return
    first, last = span
    step = 1e9 / rate_hz
    count = int((last - first) // step) + 1
    if count > MAX_ROWS:
        raise BagError(f'--rate {rate_hz:g} over {(last - first) / 1e9:.1f} s is {count} rows, '
                       f'more than {MAX_ROWS}; lower the rate or give --start/--end')
    for at in range(0, count, block):
        yield first + np.round(np.arange(at, min(count, at + block)) * step).astype(np.int64)


def stamps_of_topic(path, topic, start=None, end=None, max_rows: int = MAX_ROWS,
                    block: int = CSV_ROWS_AT_ONCE) -> Iterator[np.ndarray]:
    """
    Yield the header stamps (ns) of the messages of ``topic`` (a type with a header).

    ``block`` stamps at a time, as read. More than ``max_rows`` messages between ``start``
    and ``end``: a one-line BagError (after the rows before it).
    """
    from rosbags.typesys import get_typestore, Stores
    store = get_typestore(Stores.ROS2_JAZZY)
    reader = open_reader(path)
    try:
        conns = [c for c in reader.connections if c.topic == topic]
        if not conns:
            names = ', '.join(printable(t) for t, _ in reader.all_topics[:20]) or 'none'
            raise BagError(f'{path} has no topic {printable(topic)!r}; its topics: {names}')
        kind = conns[0].msgtype
        fields = store.fielddefs.get(kind)
        if fields is None or not fields[1] or fields[1][0][0] != 'header':
            raise BagError(f'--at-topic {printable(topic)}: its type {printable(kind)} is not '
                           'one whose first field is a std_msgs/Header (Image, PointCloud2, '
                           'CameraInfo...)')
        stamps, count = [], 0
        for _, _, raw in reader.messages(conns, start, end):
            if count >= max_rows:
                raise BagError(f'--at-topic {printable(topic)}: more than {max_rows} messages '
                               'between start and end; give --start/--end')
            if len(raw) >= 12:
                sec, nanosec = _STAMP.unpack_from(raw, 4)
                stamps.append(sec * 1_000_000_000 + nanosec)
                count += 1
                if len(stamps) == block:
                    yield np.asarray(stamps, np.int64)
                    stamps = []
        if stamps:
            yield np.asarray(stamps, np.int64)
    finally:
        reader.close()


def fixed9(x: float) -> str:
    """
    Return ``x`` with 9 decimals (nanometres; a quaternion to 1e-9), as the CSV has it.

    ``q = floor(|x| * 1e9 + 0.5)`` written as ``q // 10**9 . q % 10**9``, signed when x < 0
    and q > 0; ``|x| >= 9e9`` or not finite: ``%.17g``.
    """
    if not math.isfinite(x) or abs(x) >= 9e9:
        return '%.17g' % x
    q = int(math.floor(abs(x) * 1e9 + 0.5))
    return f"{'-' if x < 0 and q else ''}{q // 10**9}.{q % 10**9:09d}"


def csv_rows(stamps: np.ndarray, poses: np.ndarray) -> str:
    """
    Return ``stamp,x,y,z,qx,qy,qz,qw`` lines, each float by :func:`fixed9`.

    Fast path: ``_tf.csv_rows`` (C, the same characters); reference: :func:`fixed9` per
    value (``test_tf_bag.py``'s ``test_csv_rows_are_the_python_ones``).
    """
    stamps = np.ascontiguousarray(stamps, dtype=np.int64)
    poses = np.ascontiguousarray(poses, dtype=np.float64)
    if COMPILED is not None:
        return COMPILED.csv_rows(stamps, poses).decode('ascii')
    return ''.join(f'{s},' + ','.join(fixed9(v) for v in p) + '\n'
                   for s, p in zip(stamps.tolist(), poses.tolist()))


def export_tf(path, target: str, source: str, csv_path, rate_hz: float | None = None,
              at_topic: str | None = None, start: int | None = None,
              end: int | None = None) -> TfExport:
    """
    Write ``source``'s pose in ``target`` over the bag to ``csv_path`` (module doc).

    The rows are looked up and written ``CSV_ROWS_AT_ONCE`` at a time: memory does not grow
    with them. ``TfExport.dropped`` says in one line what the bag's TF held that was dropped.

    :param start: the first log time (ns) read; ``end``: the first not read.
    :raises BagError: one line (no TF, no such topic, too many rows, an output that exists).
    """
    if (rate_hz is None) == (at_topic is None):
        raise BagError('give one of --rate HZ or --at-topic TOPIC')
    if rate_hz is not None and not 0 < rate_hz <= 1e6:
        raise BagError(f'--rate must be above 0 and at most 1e6 Hz, got {rate_hz:g}')
    if os.path.lexists(csv_path):
        raise BagError(f'{csv_path}: exists; choose another path')
    core, summary = core_from_bag(path, start, end)
    for frame in (target, source):
        if frame not in core.ids:
            raise BagError(f'{path}: no frame {printable(frame)!r} on /tf or /tf_static; its '
                           f'frames: {", ".join(printable(f) for f in core.frame_names()[:30])}')
    blocks = stamps_at_rate(core, rate_hz) if rate_hz is not None else \
        stamps_of_topic(path, at_topic, start, end)
    rows = unanswered = 0
    try:
        with open(csv_path, 'x', newline='', encoding='utf-8') as stream:
            stream.write('stamp_ns,x,y,z,qx,qy,qz,qw\n')
            for stamps in blocks:
                poses = lookup_poses(core, target, source, stamps)
                answered = ~np.isnan(poses).any(axis=1)
                stream.write(csv_rows(stamps[answered], poses[answered]))
                rows += int(answered.sum())
                unanswered += int((~answered).sum())
    except BagError:
        os.unlink(csv_path)   # (only a file this call made: open 'x' refuses one that exists)
        raise
    return TfExport(rows, unanswered, os.fspath(csv_path), summary.dropped_line())


__all__ = ['export_tf', 'MAX_ROWS', 'stamps_at_rate', 'stamps_of_topic', 'tf_span', 'TfExport']
