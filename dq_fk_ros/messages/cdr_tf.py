"""
CDR readers of ``tf2_msgs/TFMessage`` and ``geometry_msgs/PoseStamped``, without objects.

:class:`TfLatest` keeps the newest serialized ``TFMessage`` of each layout and reads only
those (:func:`tf_layout`, :func:`tf_values`): dq_fk_view at kHz rates; :class:`TfReader`
reads every transform (the TF listener); :func:`parse_pose_stamped` one pose.
"""

import struct
from typing import NamedTuple

from dq_fk_ros.errors import CdrError
from dq_fk_ros.messages.cdr import CDR_LE_HEADER, COMPILED, Cursor, STAMP, U32
import numpy as np

_POSE7 = struct.Struct('<7d')


class TfLayout(NamedTuple):
    """Where a serialized ``tf2_msgs/TFMessage``'s values are; its frame ids are fixed."""

    size: int
    edges: tuple        # ((parent, child), ...) in message order
    strings: tuple      # ((start, end), ...): the count and frame-id bytes (the layout)
    stamps: tuple       # offset of each transform's stamp
    values: tuple       # offset of each transform's 7 float64 (translation, rotation x y z w)
    raw: bytes          # the message the layout was read from


def tf_layout(raw) -> TfLayout:
    """
    Read where the values of a serialized ``TFMessage`` are: a :class:`TfLayout`.

    :raises CdrError: truncated, not little-endian, or frame ids that are not UTF-8.
    """
    if len(raw) < 8 or bytes(raw[:4]) != CDR_LE_HEADER:
        raise CdrError('not little-endian CDR (or shorter than its header)')
    cursor = Cursor(raw)
    try:
        count = cursor.u32()
        if count > len(raw) // 64:  # each transform takes at least 64 bytes
            raise CdrError('more transforms than the message can hold')
        edges, strings, stamps, values = [], [], [], []
        for _ in range(count):  # (a transform starts 8-aligned: after the count or 7 doubles)
            stamps.append(cursor.pos)
            cursor.pos += 8
            names = []
            for _ in range(2):
                cursor.align(4)
                start = cursor.pos
                cursor.skip_string()  # (its length, the text, a NUL)
                strings.append((start, cursor.pos))
                names.append(bytes(raw[start + 4:cursor.pos - 1]).decode('utf-8'))
            cursor.align(8)
            if cursor.pos + 56 > len(raw):
                raise CdrError('transform runs past the end of the message')
            values.append(cursor.pos)
            cursor.pos += 56
            edges.append(tuple(names))
    except struct.error:
        raise CdrError('message ends inside a field') from None
    except UnicodeDecodeError:
        raise CdrError('a frame id is not UTF-8') from None
    strings.insert(0, (4, 8))  # the number of transforms belongs to the layout too
    return TfLayout(len(raw), tuple(edges), tuple(strings), tuple(stamps), tuple(values),
                    bytes(raw))


def tf_values(raw, layout) -> tuple:
    """Return ``([(parent, child, (x, y, z, qx, qy, qz, qw)), ...], first stamp ns)``."""
    transforms = [(parent, child, _POSE7.unpack_from(raw, at))
                  for (parent, child), at in zip(layout.edges, layout.values)]
    return transforms, tf_stamp(raw, layout)


def tf_stamp(raw, layout) -> int:
    """Return the stamp (ns) of a ``TFMessage``'s first transform (0 without transforms)."""
    if not layout.stamps:
        return 0
    sec, nanosec = STAMP.unpack_from(raw, layout.stamps[0])
    return sec * 1_000_000_000 + nanosec


def _string_checks(layout):
    """Return ``((start, bytes), ...)``: a layout's strings, adjacent ones joined."""
    out = []
    for a, b in layout.strings:
        if out and out[-1][0] + len(out[-1][1]) == a:
            out[-1] = (out[-1][0], out[-1][1] + layout.raw[a:b])
        else:
            out.append((a, layout.raw[a:b]))
    return tuple(out)


# a layout with more string runs than this is compared by one numpy gather (about 4 us for
# tiago_dual's 101 transforms, 132 runs; a startswith each: 11 us); fewer, run by run
_GATHER_FROM_RUNS = 16


def _layout_check(layout):
    """Return ``(runs, gather)``: the string runs, and ``(index, bytes)`` for many of them."""
    runs = _string_checks(layout)
    if len(runs) <= _GATHER_FROM_RUNS:
        return runs, None
    index = np.concatenate([np.arange(a, a + len(text), dtype=np.intp) for a, text in runs])
    return runs, (index, b''.join(text for _, text in runs))


def _is_layout(raw, check):
    """Whether ``raw`` (of the layout's size) has the layout's count and frame ids."""
    runs, gather = check
    if gather is not None:
        index, expected = gather
        return np.frombuffer(raw, np.uint8).take(index).tobytes() == expected
    for start, text in runs:  # (no copy of raw: startswith)
        if not raw.startswith(text, start):
            return False
    return True


def _compiled_check(check):
    """
    Return the C form of a layout's check (``_cdr.Runs``), or None (not built).

    ``Runs.match(raw)`` decides as :func:`_is_layout` (the reference; test_cdr.py's
    ``test_tf_latest_tells_layouts_apart``), a ``memcmp`` per run.
    """
    if COMPILED is None:
        return None
    runs, _ = check
    return COMPILED.Runs([at for at, _ in runs], [len(text) for _, text in runs],
                         b''.join(text for _, text in runs))


class KnownLayout:
    """
    A layout :class:`TfLatest` has seen, and its check; hashed by identity (cheaply).

    ``layout.raw`` is emptied once the check is made: a remembered layout holds its frame ids,
    never the message it was read from.
    """

    __slots__ = ('layout', 'check', 'match', 'runs', 'name_bytes')

    def __init__(self, layout):
        self.check = _layout_check(layout)
        self.layout = layout._replace(raw=b'')
        self.name_bytes = sum(b - a for a, b in layout.strings)
        compiled = self.runs = _compiled_check(self.check)
        self.match = compiled.match if compiled is not None else \
            (lambda raw, check=self.check: _is_layout(raw, check))


MAX_REMEMBERED_NAME_BYTES = 256 << 10   # a layout whose frame ids take more is not remembered


class LayoutCache:
    """
    The layouts of the serialized ``TFMessage`` s seen (by size); the oldest forgotten.

    A layout whose frame ids take more than ``MAX_REMEMBERED_NAME_BYTES`` is read for its
    message and not remembered: what the cache holds is at most ``max_layouts`` times that.
    """

    def __init__(self, max_layouts=64):
        """Remember at most ``max_layouts`` layouts."""
        self.max_layouts = max_layouts
        self._by_size = {}     # size -> [KnownLayout, ...]
        self._order = []

    def find(self, raw: bytes) -> tuple:
        """Return ``(raw's KnownLayout, the one forgotten to make room or None)`` (CdrError)."""
        for known in self._by_size.get(len(raw), ()):
            if known.match(raw):
                return known, None
        known = KnownLayout(tf_layout(raw))
        if known.name_bytes > MAX_REMEMBERED_NAME_BYTES:
            return known, None
        self._by_size.setdefault(known.layout.size, []).append(known)
        self._order.append(known)
        old = None
        if len(self._order) > self.max_layouts:
            old = self._order.pop(0)
            self._by_size[old.layout.size].remove(old)
        return known, old


class TfLatest:
    """
    Keep the newest serialized ``TFMessage`` of each layout (publisher), unread.

    :meth:`take` compares the frame-id bytes of a known layout (in C, ``_cdr.Runs``; else a
    startswith per run, or one numpy gather for a big robot's; all alike:
    ``test_tf_latest_tells_layouts_apart``);
    :meth:`pop` reads the values of only the newest message of each layout. At most
    ``max_layouts`` layouts are remembered (the oldest is forgotten beyond). The layouts are
    kept in objects hashed by identity: a ``TfLayout`` (a tuple of a whole robot's edges)
    would be hashed anew at every message (15 us for tiago_dual's).
    """

    def __init__(self, max_layouts=64):
        """Start with no layouts."""
        self._layouts = LayoutCache(max_layouts)
        self._latest = {}      # KnownLayout -> newest raw since pop()

    def take(self, raw) -> None:
        """Note ``raw`` as its layout's newest message (CdrError: unreadable)."""
        raw = raw if isinstance(raw, bytes) else bytes(raw)
        known, forgotten = self._layouts.find(raw)
        if forgotten is not None:
            self._latest.pop(forgotten, None)
        self._latest[known] = raw
        if len(self._latest) > self._layouts.max_layouts:   # (layouts too big to remember)
            self._latest.pop(next(iter(self._latest)))

    def pop(self) -> list:
        """Return ``[(transforms, stamp_ns), ...]`` of each layout's newest message; forget it."""
        latest, self._latest = self._latest, {}
        return [tf_values(raw, known.layout) for known, raw in latest.items()]

    def pop_raw(self) -> list:
        """Return ``[(layout, raw), ...]``: each layout's newest message as it came; forget."""
        latest, self._latest = self._latest, {}
        return [(known.layout, raw) for known, raw in latest.items()]


class TfReader:
    """
    Read every transform of serialized ``TFMessage`` s, each publisher's layout read once.

    :meth:`read` matches a message against the layouts seen (as :class:`TfLatest`) and
    unpacks its stamps and values; a new layout is read by :func:`tf_layout`. At most
    ``max_layouts`` are remembered. Reference: rosbags' ``deserialize_cdr``
    (test_cdr.py's ``test_tf_reader_reads_as_rosbags_reads_it``).
    """

    def __init__(self, max_layouts=64):
        """Start with no layouts."""
        self._layouts = LayoutCache(max_layouts)

    def read(self, raw) -> list:
        """Return ``[(parent, child, stamp_ns, (x, y, z, qx, qy, qz, qw)), ...]`` (CdrError)."""
        raw = raw if isinstance(raw, bytes) else bytes(raw)
        return self.unpack(raw, self.layout(raw))

    def layout(self, raw: bytes) -> TfLayout:
        """Return the layout of ``raw`` (one seen before, or read now; CdrError)."""
        return self._layouts.find(raw)[0].layout

    @staticmethod
    def unpack(raw: bytes, layout: TfLayout) -> list:
        """Return the transforms of ``raw``, a message of ``layout`` (as :meth:`read`)."""
        stamp, pose = STAMP.unpack_from, _POSE7.unpack_from
        out = []
        for (parent, child), at, value_at in zip(layout.edges, layout.stamps, layout.values):
            sec, nanosec = stamp(raw, at)
            out.append((parent, child, sec * 1_000_000_000 + nanosec, pose(raw, value_at)))
        return out


MAX_POSE_STAMPED_BYTES = 4096  # a frame id longer than some 4000 bytes is refused


def parse_pose_stamped(raw) -> tuple:
    """
    Read a serialized ``geometry_msgs/PoseStamped``: ``(stamp_ns, frame_id, pose)``.

    ``pose`` is ``(x, y, z, qx, qy, qz, qw)``. Reference: rosbags' ``deserialize_cdr``
    (``test_pose_stamped_reads_as_rosbags_reads_it``).

    :raises CdrError: not little-endian CDR, too long, truncated, trailing bytes beyond
        alignment, or a frame id that is not UTF-8.
    """
    if len(raw) < 16 or bytes(raw[:4]) != CDR_LE_HEADER:
        raise CdrError('not little-endian CDR (or shorter than its header)')
    if len(raw) > MAX_POSE_STAMPED_BYTES:
        raise CdrError(f'{len(raw)} bytes; a PoseStamped of at most '
                       f'{MAX_POSE_STAMPED_BYTES} is taken')
    sec, nanosec = STAMP.unpack_from(raw, 4)
    cursor = Cursor(raw)
    cursor.pos = 12
    cursor.skip_string()
    start = cursor.pos - U32.unpack_from(raw, 12)[0]
    try:
        frame_id = bytes(raw[start:cursor.pos - 1]).decode('utf-8')
    except UnicodeDecodeError:
        raise CdrError('frame_id is not UTF-8') from None
    cursor.align(8)
    if cursor.pos + 56 != len(raw):
        raise CdrError(f'{len(raw)} bytes; a PoseStamped with this frame id has '
                       f'{cursor.pos + 56}')
    return sec * 1_000_000_000 + nanosec, frame_id, _POSE7.unpack_from(raw, cursor.pos)


__all__ = ['KnownLayout', 'LayoutCache', 'MAX_POSE_STAMPED_BYTES', 'parse_pose_stamped',
           'TfLatest', 'TfLayout', 'tf_layout', 'TfReader', 'tf_stamp', 'tf_values']
