"""
Fast CDR (little-endian, plain CDR as ROS 2 uses) for the bag tools; numpy and struct only.

* :func:`parse_joint_state` reads a serialized ``sensor_msgs/JointState`` without building a
  message object, and reuses the joint-name tuple while the names' bytes do not change.
* :class:`CdrTemplate` serializes many messages of a fixed layout at once: the bytes of a
  message with fixed strings (frame ids) are built once; stamps and float64 fields are then
  written into an ``(N, size)`` array for a whole chunk (``PoseStamped``, ``TFMessage``).

Offsets follow the CDR rules: after the 4-byte encapsulation header, every primitive is
aligned to its size, relative to the start of the payload.
"""

import struct

import numpy as np

CDR_LE_HEADER = b'\x00\x01\x00\x00'
_U32 = struct.Struct('<I')
_STAMP = struct.Struct('<iI')


class CdrError(ValueError):
    """A serialized message that cannot be read."""


class _Cursor:
    __slots__ = ('raw', 'pos')

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

    def f64_array(self):
        count = self.u32()
        if count == 0:
            return np.empty(0)
        self.align(8)
        end = self.pos + 8 * count
        if end > len(self.raw):
            raise CdrError('float64 sequence runs past the end of the message')
        values = np.frombuffer(self.raw, '<f8', count, self.pos)
        self.pos = end
        return values


class JointStateNames:
    """Cache of the last ``name`` field's bytes and its decoded tuple."""

    __slots__ = ('raw', 'names')

    def __init__(self):
        """Start empty."""
        self.raw = None
        self.names = ()


def parse_joint_state(raw, cache=None):
    """
    Read a serialized ``sensor_msgs/JointState``: ``(stamp_ns, names, positions, velocities)``.

    :param raw: the CDR bytes, encapsulation header included.
    :param cache: a :class:`JointStateNames` shared between calls (names rarely change).
    :raises CdrError: truncated or not little-endian CDR.
    """
    if len(raw) < 16 or raw[:2] != CDR_LE_HEADER[:2]:
        raise CdrError('not a little-endian CDR message (or shorter than its header)')
    try:
        sec, nanosec = _STAMP.unpack_from(raw, 4)
        cur = _Cursor(raw)
        cur.pos = 12
        cur.skip_string()  # header.frame_id
        count = cur.u32()
        start = cur.pos
        for _ in range(count):
            cur.skip_string()
        names_raw = raw[start:cur.pos]
        if cache is not None and cache.raw == names_raw:
            names = cache.names
        else:
            names = _decode_names(raw, start, count)
            if cache is not None:
                cache.raw, cache.names = bytes(names_raw), names
        positions = cur.f64_array()
        velocities = cur.f64_array()
        cur.f64_array()  # effort: read only to check the message is complete
    except struct.error as exc:
        raise CdrError(f'message ends early ({exc})') from None
    return sec * 1_000_000_000 + nanosec, names, positions, velocities


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

    def _align(self, size):
        self.buf += bytes((-(len(self.buf) - 4)) % size)

    def u32(self, value):
        """Append a uint32 (a sequence length, say)."""
        self._align(4)
        self.buf += _U32.pack(value)

    def string(self, text):
        """Append a fixed string."""
        data = text.encode('utf-8') + b'\x00'
        self.u32(len(data))
        self.buf += data

    def stamp(self):
        """Append a ``builtin_interfaces/Time`` to be filled per message."""
        self._align(4)
        self.stamps.append(len(self.buf))
        self.buf += bytes(8)

    def f64s(self, count):
        """Append ``count`` float64 fields to be filled per message."""
        self._align(8)
        self.floats.append((len(self.buf), count))
        self.buf += bytes(8 * count)

    def fill(self, stamps_ns, values):
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


def pose_stamped_template(frame_id):
    """Template of ``geometry_msgs/PoseStamped``: 7 floats, position then x y z w."""
    t = CdrTemplate()
    t.stamp()
    t.string(frame_id)
    t.f64s(7)
    return t


def tf_message_template(edges):
    """Template of ``tf2_msgs/TFMessage`` with one transform per ``(parent, child)``."""
    t = CdrTemplate()
    t.u32(len(edges))
    for parent, child in edges:
        t.stamp()
        t.string(parent)
        t.string(child)
        t.f64s(7)
    return t
