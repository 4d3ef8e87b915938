"""
Fast CDR (little-endian, plain CDR as ROS 2 uses) for the bag tools; numpy and struct only.

* :func:`parse_joint_state` reads a serialized ``sensor_msgs/JointState`` without building a
  message object, and reuses the joint-name tuple while the names' bytes do not change.
* :class:`TfLatest` keeps the newest serialized ``tf2_msgs/TFMessage`` of each layout and
  reads only those (:func:`tf_layout`, :func:`tf_values`): dq_fk_view at kHz rates.
* :class:`CdrTemplate` serializes many messages of a fixed layout at once: the bytes of a
  message with fixed strings (frame ids) are built once; stamps and float64 fields are then
  written into an ``(N, size)`` array for a whole chunk (``PoseStamped``, ``TFMessage``).

Offsets follow the CDR rules: after the 4-byte encapsulation header, every primitive is
aligned to its size, relative to the start of the payload.

Why this file is long: the CDR layouts of the package's few message types, read and written,
one message and batches side by side (the tests hold them equal).
"""

import itertools
import operator
import struct
from typing import NamedTuple

from dq_fk_ros.errors import CdrError
from dq_fk_ros.kinematics.kernel import load_compiled
import numpy as np

# the C writer of fixed-layout messages (None: the struct packer, the reference, alone)
COMPILED, COMPILED_WHY = load_compiled('dq_fk_ros.messages._cdr')

CDR_LE_HEADER = b'\x00\x01\x00\x00'
_LE = CDR_LE_HEADER[:2]  # the representation identifier: plain CDR, little-endian
_U32 = struct.Struct('<I')
_STAMP = struct.Struct('<iI')
# a JointState naming more joints, or larger, is refused (malformed_cdr): a robot has far
# fewer, and what a message names is cached and listed (see docs/security.md)
MAX_JOINT_STATE_NAMES = 1024
MAX_JOINT_STATE_BYTES = 64 * 1024


class _Cursor:
    __slots__ = ('raw', 'pos', 'count_at')

    def __init__(self, raw):
        self.raw = raw
        self.pos = 4  # absolute offset; payload starts after the encapsulation header

    def align(self, size):
        self.pos += (-(self.pos - 4)) % size

    def u32(self):
        self.align(4)
        (value,) = _U32.unpack_from(self.raw, self.pos)
        self.pos += 4
        return value

    def skip_string(self):
        length = self.u32()
        if length == 0 or self.pos + length > len(self.raw):
            raise CdrError('string runs past the end of the message')
        self.pos += length

    def f64_span(self):
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
        cur = _Cursor(raw)
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
    sec, nanosec = _STAMP.unpack_from(raw, 4)
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
        (length,) = _U32.unpack_from(fixed, pos)
        spans.append((start + pos, fixed[pos:pos + 4 + length]))
        pos += 4 + length
    string()  # header.frame_id
    pos += (-pos) % 4
    (count,) = _U32.unpack_from(fixed, pos)
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
        (length,) = _U32.unpack_from(raw, pos)
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


class CdrTemplate:
    """
    The bytes of a fixed-layout message, and where its stamps and float64 fields go.

    Build with :meth:`u32`, :meth:`string`, :meth:`stamp` and :meth:`f64s`, in field order;
    then :meth:`fill` writes a chunk of N messages into an ``(N, size)`` uint8 array.
    """

    def __init__(self):
        """Start with the little-endian encapsulation header."""
        self.buf = bytearray(CDR_LE_HEADER)
        self.stamps = []   # offsets of (int32 sec, uint32 nanosec)
        self.floats = []   # (offset, count) of float64 runs
        self.padding = []  # offsets of alignment bytes (zero here; unset in rclpy's output)

    def _align(self, size):
        pad = (-(len(self.buf) - 4)) % size
        self.padding.extend(range(len(self.buf), len(self.buf) + pad))
        self.buf += bytes(pad)

    def u32(self, value) -> None:
        """Append a uint32 (a sequence length, say)."""
        self._align(4)
        self.buf += _U32.pack(value)

    def string(self, text) -> None:
        """Append a fixed string."""
        data = text.encode('utf-8') + b'\x00'
        self.u32(len(data))
        self.buf += data

    def stamp(self) -> None:
        """Append a ``builtin_interfaces/Time`` to be filled per message."""
        self._align(4)
        self.stamps.append(len(self.buf))
        self.buf += bytes(8)

    def f64s(self, count) -> None:
        """Append ``count`` float64 fields to be filled per message."""
        self._align(8)
        self.floats.append((len(self.buf), count))
        self.buf += bytes(8 * count)

    def fill(self, stamps_ns, values) -> np.ndarray:
        """
        Serialize N messages: ``(N, size)`` uint8, one row per message.

        :param stamps_ns: ``(N,)`` int64 nanoseconds, written to every stamp field.
        :param values: ``(N, total)`` float64, the float runs in order.
        """
        n = len(stamps_ns)
        rows = np.empty((n, len(self.buf)), np.uint8)
        rows[:] = np.frombuffer(bytes(self.buf), np.uint8)
        stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
        sec_nsec = np.stack([stamps_ns // 1_000_000_000, stamps_ns % 1_000_000_000], axis=1)
        for offset in self.stamps:
            rows[:, offset:offset + 8].view('<i4')[:] = sec_nsec
        column = 0
        for offset, count in self.floats:
            rows[:, offset:offset + 8 * count].view('<f8')[:] = values[:, column:column + count]
            column += count
        return rows

    def packer(self) -> 'CdrPacker':
        """Return a :class:`CdrPacker`: one message of this layout at a time, as ``bytes``."""
        return CdrPacker(self)

    def compiled(self, width) -> object:
        """
        Return this layout's C writer, a ``_cdr.Template`` (or None: see below).

        None when the extension is not built, or a float run is not ``width`` long.

        Its ``one(sec, nanosec, values, rows)`` fills float run i with the row
        ``values[rows[i]]`` of an ``(n, width)`` float64 array, ``each(...)`` one message per
        row; the same bytes as :meth:`packer` (test_frame_bytes.py's
        ``test_the_c_writer_equals_the_packer_byte_for_byte``).
        """
        if COMPILED is None or any(count != width for _, count in self.floats):
            return None
        return COMPILED.Template(bytes(self.buf), self.stamps,
                                 [at for at, _ in self.floats], width)


class CdrPacker:
    """
    Serialize one message of a :class:`CdrTemplate`'s layout in a single ``struct`` call.

    The template's fixed bytes (header, frame ids, padding) become ``Ns`` fields of one
    ``struct.Struct`` between the stamps (``iI``) and float64 runs (``Nd``); a precomputed
    ``operator.itemgetter`` puts constants, stamp and values in field order. The node's hot
    path: about 1.7 us for a 6-transform TFMessage where one ``pack_into`` per field takes 4.
    """

    def __init__(self, template):
        """Lay out ``template`` (its stamps and float runs, in any order of offsets)."""
        fields = sorted([(at, 'stamp', 2) for at in template.stamps] +
                        [(at, 'floats', count) for at, count in template.floats])
        buf = bytes(template.buf)
        self.size = len(buf)
        self.n_values = sum(count for _, count in template.floats)
        fmt, consts, places = ['<'], [], []
        pos = 0
        for at, kind, count in fields + [(len(buf), 'end', 0)]:
            if at > pos:  # fixed bytes up to the next field
                fmt.append(f'{at - pos}s')
                places.append(('const', len(consts)))
                consts.append(buf[pos:at])
            if kind == 'stamp':
                fmt.append('iI')
                places += [('sec', 0), ('nanosec', 0)]
                pos = at + 8
            elif kind == 'floats':
                fmt.append(f'{count}d')
                places += [('value', 0)] * count
                pos = at + 8 * count
        # arguments are gathered as consts + [sec, nanosec] + values, then reordered
        n_const, order, value = len(consts), [], 0
        for kind, k in places:
            if kind == 'const':
                order.append(k)
            elif kind == 'sec':
                order.append(n_const)
            elif kind == 'nanosec':
                order.append(n_const + 1)
            else:
                order.append(n_const + 2 + value)
                value += 1
        self._struct = struct.Struct(''.join(fmt))
        self._consts = consts
        self._order = operator.itemgetter(*order)
        if [kind for kind, _ in places[:4]] == ['const', 'sec', 'nanosec', 'const'] and \
                len(places) == 4 + self.n_values:
            # a stamped message (header, frame id, then values): no reordering needed
            self.pack = self._stamped_packer(consts)

    def _stamped_packer(self, consts):
        pack, (head, frame_id) = self._struct.pack, consts

        def pack_stamped(sec, nanosec, runs):
            try:
                if len(runs) == 1:
                    return pack(head, sec, nanosec, frame_id, *runs[0])
                return pack(head, sec, nanosec, frame_id, *itertools.chain.from_iterable(runs))
            except struct.error as exc:
                raise ValueError(f'{exc} (a stamp and {self.n_values} float64 values)') from None
        pack_stamped.__doc__ = CdrPacker.pack.__doc__
        return pack_stamped

    def pack(self, sec, nanosec, runs) -> bytes:
        """
        Return the serialized message: every stamp ``(sec, nanosec)``, the float64 runs.

        :param runs: one sequence of floats per float run of the template, in order (a pose
            per transform of a TFMessage, say); ``n_values`` floats in all.
        """
        values = self._consts + [sec, nanosec]
        extend = values.extend  # (not +=: a numpy run would broadcast instead)
        for run in runs:
            extend(run)
        if len(values) != len(self._consts) + 2 + self.n_values:
            raise ValueError(f'expected {self.n_values} float64 values, '
                             f'got {len(values) - len(self._consts) - 2}')
        return self._struct.pack(*self._order(values))


def pose_stamped_template(frame_id) -> CdrTemplate:
    """Template of ``geometry_msgs/PoseStamped``: 7 floats, position then x y z w."""
    return _stamped_template(frame_id, 7)


def twist_stamped_template(frame_id) -> CdrTemplate:
    """Template of ``geometry_msgs/TwistStamped``: 6 floats, linear then angular x y z."""
    return _stamped_template(frame_id, 6)


def _stamped_template(frame_id, count):
    """Return the template of a ``std_msgs/Header`` then ``count`` float64 fields."""
    t = CdrTemplate()
    t.stamp()
    t.string(frame_id)
    t.f64s(count)
    return t


def tf_message_template(edges) -> CdrTemplate:
    """Template of ``tf2_msgs/TFMessage`` with one transform per ``(parent, child)``."""
    t = CdrTemplate()
    t.u32(len(edges))
    for parent, child in edges:
        t.stamp()
        t.string(parent)
        t.string(child)
        t.f64s(7)
    return t


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
    cursor = _Cursor(raw)
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
    sec, nanosec = _STAMP.unpack_from(raw, layout.stamps[0])
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


class _KnownLayout:
    """A layout :class:`TfLatest` has seen, and its check; hashed by identity (cheaply)."""

    __slots__ = ('layout', 'check', 'match', 'runs')

    def __init__(self, layout):
        self.layout, self.check = layout, _layout_check(layout)
        compiled = self.runs = _compiled_check(self.check)
        self.match = compiled.match if compiled is not None else \
            (lambda raw, check=self.check: _is_layout(raw, check))


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
        self.max_layouts = max_layouts
        self._by_size = {}     # size -> [_KnownLayout, ...]
        self._latest = {}      # _KnownLayout -> newest raw since pop()
        self._order = []

    def take(self, raw) -> None:
        """Note ``raw`` as its layout's newest message (CdrError: unreadable)."""
        raw = raw if isinstance(raw, bytes) else bytes(raw)
        for known in self._by_size.get(len(raw), ()):
            if known.match(raw):
                self._latest[known] = raw
                return
        known = _KnownLayout(tf_layout(raw))
        self._by_size.setdefault(known.layout.size, []).append(known)
        self._order.append(known)
        if len(self._order) > self.max_layouts:
            old = self._order.pop(0)
            self._by_size[old.layout.size].remove(old)
            self._latest.pop(old, None)
        self._latest[known] = raw

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
        self.max_layouts = max_layouts
        self._by_size = {}
        self._order = []

    def read(self, raw) -> list:
        """Return ``[(parent, child, stamp_ns, (x, y, z, qx, qy, qz, qw)), ...]`` (CdrError)."""
        raw = raw if isinstance(raw, bytes) else bytes(raw)
        return self.unpack(raw, self.layout(raw))

    def layout(self, raw: bytes) -> TfLayout:
        """Return the layout of ``raw`` (one seen before, or read now; CdrError)."""
        known = None
        for candidate in self._by_size.get(len(raw), ()):
            if candidate.match(raw):
                known = candidate
                break
        if known is None:
            known = _KnownLayout(tf_layout(raw))
            self._by_size.setdefault(known.layout.size, []).append(known)
            self._order.append(known)
            if len(self._order) > self.max_layouts:
                old = self._order.pop(0)
                self._by_size[old.layout.size].remove(old)
        return known.layout

    @staticmethod
    def unpack(raw: bytes, layout: TfLayout) -> list:
        """Return the transforms of ``raw``, a message of ``layout`` (as :meth:`read`)."""
        stamp, pose = _STAMP.unpack_from, _POSE7.unpack_from
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
    sec, nanosec = _STAMP.unpack_from(raw, 4)
    cursor = _Cursor(raw)
    cursor.pos = 12
    cursor.skip_string()
    start = cursor.pos - _U32.unpack_from(raw, 12)[0]
    try:
        frame_id = bytes(raw[start:cursor.pos - 1]).decode('utf-8')
    except UnicodeDecodeError:
        raise CdrError('frame_id is not UTF-8') from None
    cursor.align(8)
    if cursor.pos + 56 != len(raw):
        raise CdrError(f'{len(raw)} bytes; a PoseStamped with this frame id has '
                       f'{cursor.pos + 56}')
    return sec * 1_000_000_000 + nanosec, frame_id, _POSE7.unpack_from(raw, cursor.pos)
