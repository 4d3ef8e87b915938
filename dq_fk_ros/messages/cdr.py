"""
Fast CDR (little-endian, plain CDR as ROS 2 uses) for the bag tools; numpy and struct only.

* :func:`parse_joint_state` reads a serialized ``sensor_msgs/JointState`` without building a
  message object, and reuses the joint-name tuple while the names' bytes do not change.
* :class:`Cursor`: a position in a message, aligned as CDR aligns, for the readers here and
  in :mod:`dq_fk_ros.messages.cdr_tf` (TFMessage, PoseStamped);
  :mod:`dq_fk_ros.messages.cdr_templates` writes fixed-layout messages.

Offsets follow the CDR rules: after the 4-byte encapsulation header, every primitive is
aligned to its size, relative to the start of the payload.

"""

import struct
from typing import NamedTuple

from dq_fk_ros.errors import CdrError
from dq_fk_ros.kinematics.kernel import load_compiled
import numpy as np

# the C writer of fixed-layout messages (None: the struct packer, the reference, alone)
COMPILED, COMPILED_WHY = load_compiled('dq_fk_ros.messages._cdr')

CDR_LE_HEADER = b'\x00\x01\x00\x00'
_LE = CDR_LE_HEADER[:2]  # the representation identifier: plain CDR, little-endian
U32 = struct.Struct('<I')
STAMP = struct.Struct('<iI')
# a JointState naming more joints, or larger, is refused (malformed_cdr): a robot has far
# fewer, and what a message names is cached and listed (see docs/security.md)
MAX_JOINT_STATE_NAMES = 1024
MAX_JOINT_STATE_BYTES = 64 * 1024


class Cursor:
    __slots__ = ('raw', 'pos', 'count_at')

    def __init__(self, raw):
        """Start at the payload, after the encapsulation header."""
        self.raw = raw
        self.pos = 4  # absolute offset; payload starts after the encapsulation header

    def align(self, size: int) -> None:
        """Move to the next multiple of ``size`` from the payload's start."""
        self.pos += (-(self.pos - 4)) % size

    def u32(self) -> int:
        """Read an aligned uint32."""
        self.align(4)
        (value,) = U32.unpack_from(self.raw, self.pos)
        self.pos += 4
        return value

    def skip_string(self) -> None:
        """Skip a string (its length, its bytes and NUL); CdrError past the end."""
        length = self.u32()
        if length == 0 or self.pos + length > len(self.raw):
            raise CdrError('string runs past the end of the message')
        self.pos += length

    def f64_span(self) -> tuple:
        """Skip a float64 sequence; return ``(offset, count)`` of its values."""
        self.align(4)
        self.count_at = self.pos
        count = self.u32()
        if count == 0:
            return self.pos, 0
        self.align(8)
        start, end = self.pos, self.pos + 8 * count
        if end > len(self.raw):
            raise CdrError('float64 sequence runs past the end of the message')
        self.pos = end
        return start, count


class JointStateNames:
    """
    Cache of the last ``name`` field's bytes and its decoded tuple, and of its layout.

    A stream of JointStates from one publisher repeats the same layout (size, frame id,
    names, array lengths): :func:`parse_joint_state` then checks those bytes and reuses the
    spans instead of walking the message again.
    """

    __slots__ = ('raw', 'names', 'layout')

    def __init__(self):
        """Start empty."""
        self.raw = None
        self.names = ()
        self.layout = None  # a _JointStateLayout: the last layout read


def _joint_state_spans(raw, with_counts=False):
    """
    Where the fields of a serialized JointState are: ``(names, positions, velocities, efforts)``.

    Arrays are ``(offset, count)`` of their float64 values; names are ``(offset, count,
    end)`` of the strings (from the first one's length). The stamp is always at bytes 4..12.
    ``with_counts``: also return where each array's length is, ``((offset, count), ...)``.
    """
    if len(raw) < 16 or raw[:2] != CDR_LE_HEADER[:2]:
        raise CdrError('not a little-endian CDR message (or shorter than its header)')
    if len(raw) > MAX_JOINT_STATE_BYTES:
        raise CdrError(f'{len(raw)} bytes; a JointState of at most {MAX_JOINT_STATE_BYTES} is '
                       f'taken')
    try:
        cur = Cursor(raw)
        cur.pos = 12
        cur.skip_string()  # header.frame_id
        count = cur.u32()
        if count > MAX_JOINT_STATE_NAMES:
            raise CdrError(f'{count} joint names; at most {MAX_JOINT_STATE_NAMES} are taken')
        start = cur.pos
        for _ in range(count):
            cur.skip_string()
        names = (start, count, cur.pos)
        arrays, counts = [], []
        for _ in range(3):
            arrays.append(cur.f64_span())
            counts.append((cur.count_at, arrays[-1][1]))
    except struct.error as exc:
        raise CdrError(f'message ends early ({exc})') from None
    if with_counts:
        return (names, *arrays), tuple(counts)
    return (names, *arrays)


def parse_joint_state(raw, cache=None, as_tuples=False) -> tuple:
    """
    Read a serialized ``sensor_msgs/JointState``: ``(stamp_ns, names, positions, velocities)``.

    :param raw: the CDR bytes, encapsulation header included.
    :param cache: a :class:`JointStateNames` shared between calls (names rarely change).
    :param as_tuples: positions and velocities as tuples of floats (the node's path) instead
        of float64 arrays.
    :raises CdrError: truncated or not little-endian CDR.
    """
    layout = cache.layout if cache is not None else None
    if layout is None or len(raw) != layout.size or raw[:2] != _LE \
            or layout.counts.unpack_from(raw, layout.counts_at) != layout.expected_counts \
            or (raw[12:layout.fixed_end] != layout.fixed and not layout.same_strings(raw)):
        layout = _JointStateLayout(raw, cache)
        if cache is not None:
            cache.layout = layout
    sec, nanosec = STAMP.unpack_from(raw, 4)
    (pos_at, n_pos), (vel_at, n_vel) = layout.positions, layout.velocities
    if as_tuples:
        return (sec * 1_000_000_000 + nanosec, layout.names,
                layout.position_values.unpack_from(raw, pos_at),
                layout.velocity_values.unpack_from(raw, vel_at))
    return (sec * 1_000_000_000 + nanosec, layout.names,
            np.frombuffer(raw, '<f8', n_pos, pos_at), np.frombuffer(raw, '<f8', n_vel, vel_at))


class _JointStateLayout:
    """
    Where one JointState's values are, and the bytes that say another message has the same.

    One message at a time (the node); :class:`_Layout` is the batch version (bags), held
    equal by test_cdr.py's ``test_batch_parse_equals_parsing_one_by_one``.

    Same size, same bytes from the frame id to the end of the names, and the same three
    array lengths (read in one ``struct`` call): the values are at the same offsets.
    """

    __slots__ = ('size', 'fixed_end', 'fixed', 'counts', 'counts_at', 'count_offsets',
                 'expected_counts',
                 'names', 'positions', 'velocities', 'position_values', 'velocity_values',
                 'strings')

    def __init__(self, raw, cache):
        """Walk ``raw`` once (:raises CdrError: not a readable JointState)."""
        spans, counts = _joint_state_spans(raw, with_counts=True)
        names_span, self.positions, self.velocities, _ = spans
        self.names = _names(raw, names_span, cache)
        self.size = len(raw)
        self.fixed_end = names_span[2]
        self.fixed = bytes(raw[12:self.fixed_end])
        (first, _), (second, _), (third, _) = counts
        self.counts = struct.Struct(f'<I{second - first - 4}xI{third - second - 4}xI')
        self.counts_at = first
        self.count_offsets = (first, second, third)
        self.expected_counts = tuple(n for _, n in counts)
        self.position_values = struct.Struct(f'<{self.positions[1]}d')
        self.velocity_values = struct.Struct(f'<{self.velocities[1]}d')
        self.strings = None  # (offset, bytes) of the strings, built on the first miss

    def compiled_reader(self, order, lower, upper, jump_back_ns):
        """
        Return the C short path of this layout, a ``_cdr.JointStateReader`` (None: not built).

        Used by :meth:`JointStateMerger.learn_layout`; ``order``, ``lower``, ``upper`` per
        name: its index in the merger's joint vector and its limits.
        """
        if COMPILED is None:
            return None
        if self.strings is None:
            self.strings = _string_spans(self.fixed, 12)
        mask = bytearray(len(self.fixed))  # compare the strings, not CDR's padding
        for at, text in self.strings:
            mask[at - 12:at - 12 + len(text)] = b'\xff' * len(text)
        return COMPILED.JointStateReader(
            self.size, self.fixed, bytes(mask), self.count_offsets, self.expected_counts,
            self.positions[0], self.velocities[0], order, lower, upper, jump_back_ns)

    def same_strings(self, raw):
        """
        Say whether ``raw`` has this layout's frame id and names, padding aside.

        CDR's alignment padding is not defined: a serializer may leave any bytes there (rclpy
        does), so two messages with the same names can differ in ``fixed``. Then the
        strings are compared one by one (lengths and characters), still cheaper than reading
        the message anew.
        """
        if self.strings is None:
            self.strings = _string_spans(self.fixed, 12)
        return all(raw[at:at + len(text)] == text for at, text in self.strings)


def _string_spans(fixed, start):
    """Return ``[(offset, length and characters), ...]`` of the strings in ``fixed``."""
    spans, pos = [], 0

    def string():
        nonlocal pos
        pos += (-pos) % 4
        (length,) = U32.unpack_from(fixed, pos)
        spans.append((start + pos, fixed[pos:pos + 4 + length]))
        pos += 4 + length
    string()  # header.frame_id
    pos += (-pos) % 4
    (count,) = U32.unpack_from(fixed, pos)
    spans.append((start + pos, fixed[pos:pos + 4]))
    pos += 4
    for _ in range(count):
        string()
    return spans


def _names(raw, span, cache):
    """Decode the names of ``span`` (reusing ``cache`` while their bytes are unchanged)."""
    at, count, end = span
    if cache is None:
        return _decode_names(raw, at, count)
    names_raw = bytes(raw[at:end])
    if cache.raw == names_raw:
        return cache.names
    names = _decode_names(raw, at, count)
    cache.raw, cache.names = names_raw, names
    return names


def _decode_names(raw, pos, count):
    names = []
    for _ in range(count):
        pos += (-(pos - 4)) % 4
        (length,) = U32.unpack_from(raw, pos)
        pos += 4
        try:
            names.append(bytes(raw[pos:pos + length - 1]).decode('utf-8'))
        except UnicodeDecodeError:
            raise CdrError('a joint name is not UTF-8') from None
        pos += length
    return tuple(names)


class JointStateRun(NamedTuple):
    """Consecutive messages of one layout (same names and array lengths), as arrays."""

    first: int                # index of the run's first message in the batch
    names: tuple
    stamps_ns: np.ndarray     # (k,) int64
    positions: np.ndarray     # (k, len(positions)) float64
    velocities: np.ndarray    # (k, len(velocities)) float64, often (k, 0)


class JointStateGroup(NamedTuple):
    """Messages of one layout anywhere in the batch (``rows``: their indices), as arrays."""

    rows: np.ndarray          # (k,) int64, ascending
    names: tuple
    stamps_ns: np.ndarray     # (k,) int64
    positions: np.ndarray     # (k, len(positions)) float64
    velocities: np.ndarray    # (k, len(velocities)) float64, often (k, 0)


class MalformedJointState(NamedTuple):
    """A message of the batch that is not readable CDR of a JointState."""

    index: int
    reason: str


class _Layout:
    """
    One message's layout: its size, the bytes that must match, where the values are.

    The batch version of :class:`_JointStateLayout` (see there for the test holding them equal).
    """

    def __init__(self, raw, cache):
        spans, counts = _joint_state_spans(raw, with_counts=True)
        names, self.positions, self.velocities, _ = spans
        self.names = _names(raw, names, cache)
        self.size = len(raw)
        # the bytes that say "same layout": the encapsulation, the strings (lengths and
        # characters) and the arrays' lengths; not the stamp, the values, nor the padding,
        # which CDR leaves undefined (rclpy's holds whatever its buffer held)
        fixed = np.zeros(self.size, bool)
        fixed[:4] = True
        for at, text in _string_spans(bytes(raw[12:names[2]]), 12):
            fixed[at:at + len(text)] = True
        for at, _ in counts:
            fixed[at:at + 4] = True
        self.fixed = np.flatnonzero(fixed)
        self.template = np.frombuffer(raw, np.uint8)[self.fixed]
        # the same bytes as runs, compared by memcmp in C (:meth:`matches`)
        pieces = np.split(self.fixed, np.flatnonzero(np.diff(self.fixed) != 1) + 1)
        self.runs = None if COMPILED is None else COMPILED.Runs(
            [int(p[0]) for p in pieces], [len(p) for p in pieces], self.template.tobytes())

    def matches(self, joined, starts, lengths, rows):
        """
        Return which of these messages (``rows``, their ``(k, size)`` bytes) are of this layout.

        Fast path: ``_cdr.Runs.match_many`` (a memcmp per run of fixed bytes, on the spans
        in ``joined``); reference: the numpy compare of ``rows`` with the template, held
        equal by test_cdr.py's ``test_the_compiled_batch_match_is_the_numpy_compare``.
        """
        if self.runs is None:
            return (rows[:, self.fixed] == self.template).all(axis=1)
        same = self.runs.match_many(joined, starts, lengths, self.size)
        return np.frombuffer(same, np.bool_)

    def values(self, rows):
        """Stamps, positions and velocities of ``(k, size)`` messages of this layout."""
        sec = rows[:, 4:8].copy().view('<i4')[:, 0].astype(np.int64)
        nanosec = rows[:, 8:12].copy().view('<u4')[:, 0].astype(np.int64)

        def floats(span):
            at, count = span
            return rows[:, at:at + 8 * count].copy().view('<f8')
        return sec * 1_000_000_000 + nanosec, floats(self.positions), floats(self.velocities)


def parse_joint_states(raws, cache=None, max_layouts=8) -> list:
    """
    Read a batch of serialized JointStates: runs of one layout, as arrays, in batch order.

    A layout is read from one message; every message of the same size whose bytes outside
    the stamp and the float64 values are equal shares it, and its values are read for all
    of them at once. Returns a list of :class:`JointStateRun` and
    :class:`MalformedJointState` that covers the batch in order. The values are those
    :func:`parse_joint_state` reads message by message.

    :param raws: the messages' CDR bytes.
    :param cache: a :class:`JointStateNames` shared between batches.
    :param max_layouts: layouts matched against the whole batch; messages of further
        layouts are read one by one (bounds the work when every message differs).
    """
    m = len(raws)
    if not m:
        return []
    lengths = np.fromiter(map(len, raws), np.int64, m)
    starts = np.zeros(m, np.int64)
    np.cumsum(lengths[:-1], out=starts[1:])
    return parse_joint_state_spans(b''.join(raws), starts, lengths, cache, max_layouts)


def parse_joint_state_spans(joined, starts, lengths, cache=None, max_layouts=8) -> list:
    """
    As :func:`parse_joint_states`, for messages that lie in one buffer.

    :param joined: a bytes-like object holding the messages.
    :param starts: ``(m,)`` int64, where message i starts in ``joined``.
    :param lengths: ``(m,)`` int64, its length (every span inside ``joined``).
    """
    groups, malformed = group_joint_state_spans(joined, starts, lengths, cache, max_layouts)
    m = len(starts)
    if not m:
        return []
    layout_of = np.full(m, -1)
    rank = np.zeros(m, np.int64)     # position of a message among its layout's messages
    for g, group in enumerate(groups):
        layout_of[group.rows] = g
        rank[group.rows] = np.arange(len(group.rows))
    reasons = {}
    for item in malformed:
        layout_of[item.index] = -2
        reasons[item.index] = item.reason
    out = []
    breaks = np.flatnonzero((layout_of[1:] != layout_of[:-1]) | (layout_of[1:] == -2)) + 1
    for a, b in zip(np.concatenate([[0], breaks]), np.concatenate([breaks, [m]])):
        a, b = int(a), int(b)
        lid = layout_of[a]
        if lid == -2:
            out.append(MalformedJointState(a, reasons[a]))
            continue
        r, group = rank[a], groups[lid]
        out.append(JointStateRun(a, group.names, group.stamps_ns[r:r + b - a],
                                 group.positions[r:r + b - a], group.velocities[r:r + b - a]))
    return out


def group_joint_state_spans(joined, starts, lengths, cache=None, max_layouts=8) -> tuple:
    """
    Read messages that lie in one buffer as one group per layout: ``(groups, malformed)``.

    :func:`parse_joint_state_spans` cuts the same groups into runs of consecutive
    messages; several publishers' interleaved messages are a run each, but one group per
    layout here (the bag tool merges them so, ``merge_many`` with each message's place).
    ``groups``: :class:`JointStateGroup` s, in the order of their first message;
    ``malformed``: :class:`MalformedJointState` s. Arguments as there.
    """
    m = len(starts)
    if not m:
        return [], []
    joined = np.frombuffer(joined, np.uint8)
    starts = np.asarray(starts, np.int64)
    lengths = np.asarray(lengths, np.int64)
    if starts.min() < 0 or lengths.min() < 0 or (starts + lengths).max() > len(joined):
        raise ValueError('a message span lies outside the buffer')
    done = np.zeros(m, bool)
    groups, malformed = [], []
    todo = np.arange(m)
    while len(todo):
        first = int(todo[0])
        try:
            layout = _Layout(joined[starts[first]:starts[first] + lengths[first]].tobytes(),
                             cache)
        except CdrError as exc:
            malformed.append(MalformedJointState(first, str(exc)))
            done[first] = True
            todo = todo[1:]
            continue
        same = todo[lengths[todo] == layout.size] if len(groups) < max_layouts else todo[:1]
        rows = _rows(joined, starts, same, layout.size)
        match = layout.matches(joined, starts[same], lengths[same], rows)
        members = same[match]
        done[members] = True
        taken = rows if match.all() else rows[match]   # (all of them: no copy)
        groups.append(JointStateGroup(members, layout.names, *layout.values(taken)))
        todo = todo[~done[todo]]
    return groups, malformed


def _rows(joined, starts, which, size):
    """Return the ``(len(which), size)`` bytes of messages ``which`` (a view if they abut)."""
    first = starts[which[0]]
    if len(which) == len(starts) and first + size * len(which) <= len(joined) and \
            (starts == first + size * np.arange(len(starts))).all():
        return joined[first:first + size * len(which)].reshape(len(which), size)
    return joined[starts[which][:, None] + np.arange(size)]
