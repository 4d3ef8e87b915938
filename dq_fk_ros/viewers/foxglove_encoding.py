"""
Foxglove messages encoded straight from the bytes a ROS message came in, at a flush's cost.

A tiago_dual ``/tf`` (101 transforms) made into ``foxglove.FrameTransforms`` objects and
encoded by the SDK takes some 280 us; :class:`FrameTransformsEncoder` writes the same
protobuf from a template of the layout (frame ids, tags, lengths laid out once) with the
message's stamp and its 7 values per transform copied in (some 20 us). A ``JointState``'s
JSON is its names' text, made once per set of names, and its values (:func:`joint_state_json`).

The references: :func:`~dq_fk_ros.viewers.foxglove_feed.frame_transforms` (the SDK's objects and
its encoder) and ``json.dumps`` of the fields; test_foxglove_encoding.py holds them equal,
decoded with google.protobuf and json.
"""

import json
import math

import numpy as np

_DOUBLE_TAGS = (0x09, 0x11, 0x19, 0x21)   # fields 1..4 of a message, wire type 1 (64-bit)
# a form's index arrays take some 17 bytes a byte of the message: the largest /tf written
# from a template, and the forms kept per layout (one a stamp length: in practice one or two)
MAX_TEMPLATED_BYTES = 256 << 10
MAX_FORMS = 2


def varint(value: int) -> bytes:
    """Return a non-negative int in protobuf's variable-length encoding (shortest form)."""
    out = bytearray()
    while True:
        low = value & 0x7F
        value >>= 7
        if value:
            out.append(low | 0x80)
        else:
            out.append(low)
            return bytes(out)


def _field(number: int, body: bytes) -> bytes:
    """Return a length-delimited field (wire type 2): tag, length, body."""
    return varint(number << 3 | 2) + varint(len(body)) + body


class _Form:
    """A layout's FrameTransforms for stamps whose varints have given lengths."""

    def __init__(self, edges, value_offsets, sec_len, nsec_len):
        stamp_len = 1 + sec_len + 1 + nsec_len
        template, stamp_at, value_src, value_dst = bytearray(), [], [], []
        for (parent, child), at in zip(edges, value_offsets):
            body = bytearray(_field(1, bytes(stamp_len)))       # timestamp, filled per call
            stamp = len(body) - stamp_len
            body += _field(2, parent.encode('utf-8')) + _field(3, child.encode('utf-8'))
            doubles = []   # (index of the value in the transform's 7, offset in body)
            for number, first, count in ((4, 0, 3), (5, 3, 4)):   # translation, rotation
                part = b''.join(bytes([_DOUBLE_TAGS[k]]) + bytes(8) for k in range(count))
                field = _field(number, part)
                start = len(body) + len(field) - len(part)
                doubles += [(first + k, start + 9 * k + 1) for k in range(count)]
                body += field
            head = varint(1 << 3 | 2) + varint(len(body))
            base = len(template) + len(head)
            stamp_at.append(base + stamp)
            for i, pos in doubles:
                value_src.append(at + 8 * i + np.arange(8))
                value_dst.append(base + pos + np.arange(8))
            template += head + body
        self.template = np.frombuffer(bytes(template), np.uint8)
        self.stamp_dst = (np.array(stamp_at, np.intp)[:, None]
                          + np.arange(stamp_len)).reshape(-1)
        self.value_src = np.concatenate(value_src or [np.zeros(0)]).astype(np.intp)
        self.value_dst = np.concatenate(value_dst or [np.zeros(0)]).astype(np.intp)
        self.count = len(stamp_at)


class FrameTransformsEncoder:
    """
    ``foxglove.FrameTransforms`` (protobuf) of one ``/tf`` layout, from its serialized messages.

    :param layout: the message's :class:`~dq_fk_ros.messages.cdr_tf.TfLayout` (its edges, where
        each transform's 7 float64 are: translation x y z, rotation x y z w).
    """

    def __init__(self, layout):
        """Lay nothing out yet: a form is made for each stamp length seen (at most 25)."""
        self.layout = layout
        self._forms = {}

    def encode(self, raw: bytes, stamp_ns: int) -> bytes:
        """
        Return the FrameTransforms of ``raw`` (of this layout), every transform at ``stamp_ns``.

        Raises ``OverflowError`` for a stamp before 1970 (as ``foxglove.Timestamp``).
        """
        sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
        if sec < 0 or sec >= 1 << 64:
            raise OverflowError('a stamp Foxglove cannot carry')
        stamp = b'\x08' + varint(sec) + b'\x10' + varint(nsec)
        key = (len(varint(sec)), len(varint(nsec)))
        form = self._forms.get(key)
        if form is None:
            if len(self._forms) >= MAX_FORMS:   # stamps of every length: keep memory bounded
                self._forms.clear()
            form = self._forms[key] = _Form(self.layout.edges, self.layout.values, *key)
        out = form.template.copy()
        if form.count:
            out[form.stamp_dst] = np.tile(np.frombuffer(stamp, np.uint8), form.count)
            out[form.value_dst] = np.frombuffer(raw, np.uint8)[form.value_src]
        return out.tobytes()


def joint_state_json(stamp_ns, names, positions, velocities, names_text=None) -> str:
    """
    Return a JointState's fields as JSON: header (stamp, frame_id ''), name, position, velocity.

    A value that is not finite is ``null`` (JSON has no NaN). ``names_text``: the names
    already as JSON text (made once per set of names), else made here.
    """
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    if names_text is None:
        names_text = json.dumps(list(names))
    return (f'{{"header":{{"stamp":{{"sec":{sec},"nanosec":{nanosec}}},"frame_id":""}},'
            f'"name":{names_text},"position":[{_numbers(positions)}],'
            f'"velocity":[{_numbers(velocities)}]}}')


def _numbers(values) -> str:
    """Return float64 values as JSON numbers (their repr, as json's), null where not finite."""
    values = np.asarray(values, dtype=np.float64)
    if np.isfinite(values).all():
        return ','.join(map(float.__repr__, values.tolist()))
    return ','.join(float.__repr__(v) if math.isfinite(v) else 'null' for v in values.tolist())


__all__ = ['FrameTransformsEncoder', 'joint_state_json', 'varint']
