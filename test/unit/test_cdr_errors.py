"""What a JointState reader says of each malformed message, word for word, and its bounds."""

import struct

from dq_fk_ros.messages.cdr import (CdrError, JointStateNames, MAX_JOINT_STATE_BYTES,
                                    MAX_JOINT_STATE_NAMES, parse_joint_state)
import pytest
from test_cdr import joint_state_bytes


def refusal(raw):
    """Return the text of the CdrError ``raw`` raises."""
    with pytest.raises(CdrError) as caught:
        parse_joint_state(raw)
    return str(caught.value)


def test_each_malformed_message_is_said_as_it_is():
    raw = joint_state_bytes(['a'], [1.0])
    assert refusal(raw[:15]) == 'not a little-endian CDR message (or shorter than its header)'
    assert refusal(raw[:16]) == 'string runs past the end of the message'
    bad = bytearray(joint_state_bytes(['ab'], [1.0]))
    at = bad.index(b'ab\x00')
    bad[at] = 0xff
    assert refusal(bytes(bad)) == 'a joint name is not UTF-8'
    many = bytearray(joint_state_bytes(['a'], [1.0]))
    at = many.index(struct.pack('<Id', 1, 1.0))   # the positions' count, then the value
    many[at:at + 4] = struct.pack('<I', 3)
    assert refusal(bytes(many)) == 'float64 sequence runs past the end of the message'


def test_the_size_and_name_bounds_hold_at_their_edges():
    base = len(joint_state_bytes(['a'], []))   # (no float64: sizes in 4-byte steps)
    # the frame id grown to make the message exactly the bound (padding moves with it: the
    # length that does it is looked for), then one 4-byte step more
    frame = next('f' * n for n in range(MAX_JOINT_STATE_BYTES - base - 8,
                                        MAX_JOINT_STATE_BYTES - base + 8)
                 if len(joint_state_bytes(['a'], [], frame_id='f' * n)) ==
                 MAX_JOINT_STATE_BYTES)
    at_bound = joint_state_bytes(['a'], [], frame_id=frame)
    assert len(at_bound) == MAX_JOINT_STATE_BYTES
    assert parse_joint_state(at_bound)[1] == ('a',)
    over = joint_state_bytes(['a'], [], frame_id=frame + 'ffff')
    assert refusal(over) == (f'{len(over)} bytes; a JointState of at most '
                             f'{MAX_JOINT_STATE_BYTES} is taken')
    names = [f'{k:x}' for k in range(MAX_JOINT_STATE_NAMES)]
    assert len(parse_joint_state(joint_state_bytes(names, []))[1]) == MAX_JOINT_STATE_NAMES
    more = joint_state_bytes(names + ['x'], [])
    assert refusal(more) == (f'{MAX_JOINT_STATE_NAMES + 1} joint names; at most '
                             f'{MAX_JOINT_STATE_NAMES} are taken')


def test_a_new_layout_with_the_same_names_reuses_the_cached_names():
    cache = JointStateNames()
    first = parse_joint_state(joint_state_bytes(['a', 'b'], [1, 2]), cache)[1]
    assert cache.names is first and cache.raw is not None
    # another size (velocities, a frame id): a new layout, the names' bytes unchanged
    second = parse_joint_state(joint_state_bytes(['a', 'b'], [1, 2], [3, 4], frame_id='f'),
                               cache)[1]
    assert second is first
    third = parse_joint_state(joint_state_bytes(['a', 'c'], [1, 2]), cache)[1]
    assert third == ('a', 'c') and cache.names is third
