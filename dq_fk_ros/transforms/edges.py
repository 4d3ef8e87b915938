"""
One child frame's transforms over time (tf2's ``TimeCache`` and ``StaticCache``), in arrays.

:class:`MovingEdge` keeps the samples of a ``/tf`` edge oldest first in ``array`` objects
(int64 stamps and parent ids, 7 float64 per sample) that ``transforms/_tf.c`` reads and
appends to; :class:`StaticEdge` holds one transform valid at every time. Their rules are
tf2's ``cache.cpp``: insertion, pruning by the cache time, duplicates, and which samples
answer a time (:meth:`MovingEdge.find`); :mod:`dq_fk_ros.transforms.buffer_core` walks them.
One rule is not Jazzy's: an edge holds one sample per stamp (a repeated stamp with other
values is refused, tf2's ``TF_REPEATED_DATA`` of ROS 1); Jazzy's ``insertData`` keeps every
distinct sample of a stamp, scanning them all at each insert, so that one peer repeating a
stamp grows an edge without bound and slows every insert.
"""

from array import array
from bisect import bisect_left, bisect_right

from dq_fk_ros.transforms.pose_math import screw_interpolate, slerp

STORED, OLD, REPEATED = 0, 1, 2   # what MovingEdge.insert did with a sample


def display_time(stamp_ns: int) -> str:
    """Return a time as tf2's ``displayTimePoint`` prints it (seconds, 6 decimals)."""
    return f'{stamp_ns / 1e9:.6f}'


class StaticEdge:
    """One transform valid at every time (tf2's ``StaticCache``)."""

    __slots__ = ('parent', 'values')
    static = True

    def __init__(self, parent, values):
        self.parent, self.values = parent, values

    def get(self, time_ns: int) -> tuple:
        """Return ``(parent, values, None)``: the one transform, at any time."""
        return self.parent, self.values, None

    def latest(self) -> tuple:
        """Return ``(0, parent)``: a static edge has no time (tf2's StaticCache)."""
        return 0, self.parent

    def newest_stamp(self) -> int:
        """Return 0: no time."""
        return 0

    def oldest_stamp(self) -> int:
        """Return 0: no time."""
        return 0

    def __len__(self):
        return 1


class MovingEdge:
    """
    A child frame's samples, oldest first, in arrays (tf2's ``TimeCache``).

    The arrays have room beyond ``count``, so that a sample appended in order is a write
    into them (``_tf.append_many`` writes there too); samples ``[start:count]`` are live,
    those before ``start`` pruned. When full, the pruned ones are dropped if they are a
    quarter or more, else the arrays doubled: at most about 4/3 of the live samples' room
    is held once the cache time is filled.
    """

    __slots__ = ('stamps', 'parents', 'values', 'start', 'count', 'cache_ns')
    static = False

    def __init__(self, cache_ns, room=8):
        self.stamps = array('q', bytes(8 * room))   # ns, ascending
        self.parents = array('q', bytes(8 * room))
        self.values = array('d', bytes(56 * room))  # 7 per sample: x y z qx qy qz qw
        self.start = 0
        self.count = 0
        self.cache_ns = cache_ns

    @classmethod
    def of(cls, cache_ns, stamps: bytes, parents: bytes, values: bytes) -> 'MovingEdge':
        """Return a cache holding these samples (int64, int64, 7 float64 each; sorted)."""
        made = cls(cache_ns, room=0)
        made.stamps, made.parents, made.values = (array('q', stamps), array('q', parents),
                                                  array('d', values))
        made.count = len(made.stamps)
        return made

    def __len__(self):
        return self.count - self.start

    def newest_stamp(self) -> int:
        """Return the newest sample's stamp (ns; 0 when empty)."""
        return self.stamps[self.count - 1] if self.count > self.start else 0

    def oldest_stamp(self) -> int:
        """Return the oldest live sample's stamp (ns; 0 when empty)."""
        return self.stamps[self.start] if self.count > self.start else 0

    def latest(self) -> tuple:
        """Return ``(newest stamp, its parent id)``; ``(0, 0)`` when empty."""
        if self.count <= self.start:
            return 0, 0
        return self.stamps[self.count - 1], self.parents[self.count - 1]

    def _room(self):
        """Make room for one more sample when full: drop pruned ones, or double the arrays."""
        if self.count < len(self.stamps):
            return
        if self.start * 4 >= self.count:   # a quarter or more pruned: moved down, no growth
            live = self.count - self.start
            self.stamps[:live] = self.stamps[self.start:self.count]
            self.parents[:live] = self.parents[self.start:self.count]
            self.values[:7 * live] = self.values[7 * self.start:7 * self.count]
            self.start, self.count = 0, live
        if self.count == len(self.stamps):
            more = max(8, self.count)
            self.stamps.frombytes(bytes(8 * more))
            self.parents.frombytes(bytes(8 * more))
            self.values.frombytes(bytes(56 * more))

    def _same(self, k, parent, values):
        return self.parents[k] == parent and tuple(self.values[7 * k:7 * k + 7]) == values

    def insert(self, stamp: int, parent: int, values: tuple) -> int:
        """
        Store a sample as tf2's ``TimeCache::insertData``; return STORED, OLD or REPEATED.

        OLD: older than the cache time before the newest. REPEATED: the edge holds a sample
        of this stamp already, with another parent or values (an exact duplicate is STORED,
        once). One sample per stamp, found by bisection: a peer repeating one stamp costs
        O(log n) an insert, never a scan of the samples sharing it.
        """
        stamps, count = self.stamps, self.count
        if count > self.start:
            newest = stamps[count - 1]
            self.start = bisect_left(stamps, newest - self.cache_ns, self.start, count)
            if stamp < newest - self.cache_ns:
                return OLD
            at = bisect_left(stamps, stamp, self.start, count)
            if at < count and stamps[at] == stamp:
                return STORED if self._same(at, parent, values) else REPEATED
        else:
            at = count
        before = self.start
        self._room()
        at -= before - self.start   # compaction moved the live samples down by the pruned
        stamps, count = self.stamps, self.count
        if at < count:   # out of order: the later samples move up one
            stamps[at + 1:count + 1] = stamps[at:count]
            self.parents[at + 1:count + 1] = self.parents[at:count]
            self.values[7 * at + 7:7 * count + 7] = self.values[7 * at:7 * count]
        stamps[at] = stamp
        self.parents[at] = parent
        self.values[7 * at:7 * at + 7] = array('d', values)
        self.count = count + 1
        return STORED

    def find(self, time_ns: int) -> tuple:
        """
        Return ``(k, k2, error)``: sample k alone (k2 None), or k and the newer k2 around t.

        ``error`` is ``(kind, text)`` when no sample answers (k is None then).
        """
        n = len(self)
        if not n:
            return None, None, ('empty', '')
        stamps = self.stamps
        last = self.count - 1
        if time_ns == 0:
            return last, None, None
        if n == 1:
            if stamps[last] == time_ns:
                return last, None, None
            return None, None, ('extrapolation', f'Lookup would require extrapolation at time '
                                f'{display_time(time_ns)}, but only time '
                                f'{display_time(stamps[last])} is in the buffer')
        newest, oldest = stamps[last], stamps[self.start]
        if time_ns == newest:
            return last, None, None
        if time_ns == oldest:
            return self.start, None, None
        if time_ns > newest:
            return None, None, ('extrapolation', 'Lookup would require extrapolation into the '
                                f'future.  Requested time {display_time(time_ns)} but the '
                                f'latest data is at time {display_time(newest)}')
        if time_ns < oldest:
            return None, None, ('extrapolation', 'Lookup would require extrapolation into the '
                                f'past.  Requested time {display_time(time_ns)} but the '
                                f'earliest data is at time {display_time(oldest)}')
        k = bisect_right(stamps, time_ns, self.start, self.count) - 1
        return k, k + 1, None

    def get(self, time_ns: int, sclerp: bool = False) -> tuple:
        """Return ``(parent, values, None)`` at ``time_ns``, or ``(0, None, error)``."""
        k, k2, error = self.find(time_ns)
        if k is None:
            return 0, None, error
        v = self.values
        if k2 is None or self.parents[k] != self.parents[k2]:
            return self.parents[k], tuple(v[7 * k:7 * k + 7]), None
        t0, t1 = self.stamps[k], self.stamps[k2]
        ratio = (time_ns - t0) / (t1 - t0)
        a, b = v[7 * k:7 * k + 7], v[7 * k2:7 * k2 + 7]
        if sclerp:
            return self.parents[k], screw_interpolate(a, b, ratio), None
        s = 1.0 - ratio
        return self.parents[k], (s * a[0] + ratio * b[0], s * a[1] + ratio * b[1],
                                 s * a[2] + ratio * b[2]) + slerp(a[3:], b[3:], ratio), None


__all__ = ['display_time', 'MovingEdge', 'OLD', 'REPEATED', 'StaticEdge', 'STORED']
