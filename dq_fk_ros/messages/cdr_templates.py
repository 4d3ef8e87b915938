"""
CDR writers of fixed-layout messages: the bytes built once, stamps and values written per row.

:class:`CdrTemplate` serializes many messages of a fixed layout at once: the bytes of a
message with fixed strings (frame ids) are built once; stamps and float64 fields are then
written into an ``(N, size)`` array for a whole chunk (``PoseStamped``, ``TFMessage``);
:class:`CdrPacker` the same for one message at a time (the node's hot path).
"""

import itertools
import operator
import struct

from dq_fk_ros.messages.cdr import CDR_LE_HEADER, COMPILED, U32
import numpy as np


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
        self.buf += U32.pack(value)

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


__all__ = ['CdrPacker', 'CdrTemplate', 'pose_stamped_template', 'tf_message_template',
           'twist_stamped_template']
