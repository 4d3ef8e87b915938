"""The fast CDR reader and templates against rosbags' own (independent) CDR implementation."""

import random
import re
import struct

from dq_fk_ros.messages.cdr import (CDR_LE_HEADER, CdrError, group_joint_state_spans,
                                    JointStateNames, JointStateRun, MalformedJointState,
                                    parse_joint_state, parse_joint_states)
from dq_fk_ros.messages.cdr_templates import (pose_stamped_template, tf_message_template,
                                              twist_stamped_template)
from dq_fk_ros.messages.cdr_tf import tf_layout
from hypothesis import given, settings, strategies as st
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

TS = get_typestore(Stores.ROS2_JAZZY)
JointState = TS.types['sensor_msgs/msg/JointState']
Header = TS.types['std_msgs/msg/Header']
Time = TS.types['builtin_interfaces/msg/Time']


def joint_state_bytes(names, positions, velocities=(), stamp_ns=0, frame_id=''):
    msg = JointState(header=Header(stamp=Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9),
                                   frame_id=frame_id),
                     name=list(names), position=np.array(positions, dtype=float),
                     velocity=np.array(velocities, dtype=float), effort=np.zeros(0))
    return bytes(TS.serialize_cdr(msg, 'sensor_msgs/msg/JointState'))


@pytest.mark.parametrize('names, positions, velocities, frame_id', [
    (['a', 'bb', 'ccc'], [0.1, -2.0, 3.5], [], ''),
    (['joint_1', 'j2'], [1.0, 2.0], [0.5, -0.5], 'base'),
    (['x'], [np.pi], [1.0], 'odd_length_frame'),
    ([], [], [], ''),
    (['a', 'b'], [0.1], [], 'f'),  # lengths differ: still readable, rejected later
])
def test_parse_matches_rosbags(names, positions, velocities, frame_id):
    raw = joint_state_bytes(names, positions, velocities, 1_700_000_123_456_789_012, frame_id)
    stamp, got_names, got_pos, got_vel = parse_joint_state(raw)
    assert stamp == 1_700_000_123_456_789_012
    assert got_names == tuple(names)
    np.testing.assert_array_equal(got_pos, positions)
    np.testing.assert_array_equal(got_vel, velocities)


def test_names_are_reused_while_unchanged():
    cache = JointStateNames()
    first = parse_joint_state(joint_state_bytes(['a', 'b'], [1, 2]), cache)[1]
    second = parse_joint_state(joint_state_bytes(['a', 'b'], [3, 4]), cache)[1]
    third = parse_joint_state(joint_state_bytes(['a', 'c'], [3, 4]), cache)[1]
    assert first is second and third == ('a', 'c')


@pytest.mark.parametrize('cut', [3, 10, 20, 30, -9, -1])
def test_truncated_messages_raise_cdr_error(cut):
    raw = joint_state_bytes(['joint_1', 'joint_2'], [1.0, 2.0], [3.0, 4.0])
    with pytest.raises(CdrError):
        parse_joint_state(raw[:cut])


def test_big_endian_is_refused():
    raw = bytearray(joint_state_bytes(['a'], [1.0]))
    raw[1] = 0
    with pytest.raises(CdrError, match='little-endian'):
        parse_joint_state(bytes(raw))


def test_a_broken_header_is_refused_after_its_layout_was_cached_too():
    cache = JointStateNames()
    raw = joint_state_bytes(['a'], [1.0])
    parse_joint_state(raw, cache)
    for at, value in ((0, 7), (1, 0)):  # not plain CDR, or big-endian: the same size
        broken = bytearray(raw)
        broken[at] = value
        with pytest.raises(CdrError, match='little-endian'):
            parse_joint_state(bytes(broken), cache)


def test_pose_stamped_template_deserializes_to_the_values():
    rows = pose_stamped_template('world').fill(
        np.array([5_000_000_001, 7]), np.array([[1, 2, 3, 0.5, 0.5, 0.5, 0.5],
                                                [-1, -2, -3, 0, 0, 0, 1.0]]))
    msg = TS.deserialize_cdr(rows[0].tobytes(), 'geometry_msgs/msg/PoseStamped')
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (5, 1)
    assert msg.header.frame_id == 'world'
    p, o = msg.pose.position, msg.pose.orientation
    assert [p.x, p.y, p.z, o.x, o.y, o.z, o.w] == [1, 2, 3, 0.5, 0.5, 0.5, 0.5]
    assert TS.deserialize_cdr(rows[1].tobytes(), 'geometry_msgs/msg/PoseStamped'
                              ).header.stamp.nanosec == 7


def test_tf_message_template_deserializes_to_the_values():
    edges = [('world', 'base'), ('base', 'link_with_a_longer_name'), ('l', 'x')]
    values = np.arange(21, dtype=float)[None, :] + 0.25
    row = tf_message_template(edges).fill(np.array([123_000_000_456]), values)[0]
    msg = TS.deserialize_cdr(row.tobytes(), 'tf2_msgs/msg/TFMessage')
    assert [(t.header.frame_id, t.child_frame_id) for t in msg.transforms] == edges
    for k, t in enumerate(msg.transforms):
        tr, rot = t.transform.translation, t.transform.rotation
        assert [tr.x, tr.y, tr.z, rot.x, rot.y, rot.z, rot.w] == list(values[0, 7 * k:7 * k + 7])
        assert (t.header.stamp.sec, t.header.stamp.nanosec) == (123, 456)
    assert len(row) == len(TS.serialize_cdr(msg, 'tf2_msgs/msg/TFMessage'))


@pytest.mark.parametrize('template', [
    pose_stamped_template('world'), twist_stamped_template('base_link'),
    tf_message_template([('world', 'base'), ('base', 'link_with_a_longer_name'), ('l', 'x')]),
    tf_message_template([('w', 'a')])], ids=['pose', 'twist', 'tf3', 'tf1'])
def test_one_message_packed_equals_the_template_filled(template):
    """One message packed (one struct call, the node's path) is what fill() writes."""
    packer = template.packer()
    rng = np.random.default_rng(packer.n_values)
    for sec, nanosec in [(0, 0), (1, 999_999_999), (2**31 - 1, 5), (-3, 7)]:
        values = rng.normal(size=packer.n_values)
        runs = [values[k:k + 7].tolist() for k in range(0, len(values), 7)] \
            if packer.n_values % 7 == 0 else [values[:3].tolist(), values[3:].tolist()]
        ours = packer.pack(sec, nanosec, runs)
        row = template.fill(np.array([sec * 1_000_000_000 + nanosec]), values[None, :])[0]
        assert ours == row.tobytes()
        assert len(ours) == packer.size
        with pytest.raises(ValueError, match='float64 values'):
            packer.pack(sec, nanosec, runs[:-1])
        with pytest.raises(ValueError, match='float64 values'):
            packer.pack(sec, nanosec, runs + [[1.0]])


def mixed_messages(rng, count):
    """Messages of several layouts (some of equal size), in runs, with malformed ones."""
    kinds = [(['a', 'b', 'c'], 0, ''), (['a', 'b', 'd'], 0, ''),      # same size, other name
             (['a', 'b', 'c'], 3, ''), (['a', 'b', 'c'], 0, 'base'),  # velocities, frame id
             (['c'], 0, ''), ([], 0, '')]
    raws = []
    while len(raws) < count:
        names, n_vel, frame = kinds[rng.integers(len(kinds))]
        for _ in range(int(rng.integers(1, 12))):
            stamp = int(rng.integers(0, 2**60))
            raw = joint_state_bytes(names, rng.normal(size=len(names)),
                                    rng.normal(size=n_vel), stamp, frame)
            if rng.random() < 0.05:
                raw = raw[:int(rng.integers(0, len(raw)))]  # truncated
            raws.append(memoryview(raw) if rng.random() < 0.5 else raw)
    return raws[:count]


@pytest.mark.parametrize('max_layouts', [1, 3, 8])
@pytest.mark.parametrize('seed', range(4))
def test_batch_parse_equals_parsing_one_by_one(seed, max_layouts):
    rng = np.random.default_rng(seed)
    raws = mixed_messages(rng, 400)
    expected = []
    for raw in raws:
        try:
            expected.append(parse_joint_state(raw))
        except CdrError as exc:
            expected.append(str(exc))
    got = [None] * len(raws)
    covered = 0
    for item in parse_joint_states(raws, JointStateNames(), max_layouts):
        if isinstance(item, MalformedJointState):
            assert item.index == covered
            got[item.index] = item.reason
            covered += 1
            continue
        assert isinstance(item, JointStateRun) and item.first == covered
        assert len(item.positions) == len(item.velocities) == len(item.stamps_ns)
        for j in range(len(item.stamps_ns)):
            got[item.first + j] = (int(item.stamps_ns[j]), item.names, item.positions[j],
                                   item.velocities[j])
        covered += len(item.stamps_ns)
    assert covered == len(raws)
    for g, e in zip(got, expected):
        if isinstance(e, str):
            assert g == e
        else:
            assert (g[0], g[1]) == (e[0], e[1])
            np.testing.assert_array_equal(g[2], e[2])
            np.testing.assert_array_equal(g[3], e[3])


@pytest.mark.parametrize('max_layouts', [1, 8])
@pytest.mark.parametrize('seed', range(3))
def test_groups_of_a_batch_hold_each_message_once_as_one_by_one_reads_it(seed, max_layouts):
    rng = np.random.default_rng(seed)
    raws = [bytes(r) for r in mixed_messages(rng, 300)]
    rng.shuffle(raws)   # interleaved layouts: groups are not runs
    starts = np.cumsum([0] + [len(r) for r in raws[:-1]]).astype(np.int64)
    lengths = np.array([len(r) for r in raws], np.int64)
    groups, malformed = group_joint_state_spans(b''.join(raws), starts, lengths,
                                                JointStateNames(), max_layouts)
    seen = np.zeros(len(raws), int)
    for item in malformed:
        seen[item.index] += 1
        with pytest.raises(CdrError, match=re.escape(item.reason)):
            parse_joint_state(raws[item.index])
    for group in groups:
        assert (np.diff(group.rows) > 0).all()
        for j, i in enumerate(group.rows.tolist()):
            seen[i] += 1
            stamp, names, positions, velocities = parse_joint_state(raws[i])[:4]
            assert (int(group.stamps_ns[j]), group.names) == (stamp, names)
            np.testing.assert_array_equal(group.positions[j], positions)
            np.testing.assert_array_equal(group.velocities[j], velocities)
    assert (seen == 1).all()


def test_batch_parse_makes_one_run_of_a_uniform_batch():
    raws = [joint_state_bytes(['j1', 'j2'], [k, -k], [], 10**9 * k) for k in range(500)]
    runs = parse_joint_states(raws)
    assert len(runs) == 1 and runs[0].positions.shape == (500, 2)
    assert runs[0].stamps_ns.tolist() == [10**9 * k for k in range(500)]
    assert parse_joint_states([]) == []


@given(st.lists(st.tuples(st.sampled_from([('a', 'b', 'c'), ('c', 'b', 'a'), ('a', 'b'),
                                           ('ab', 'c', 'd'), ('a', 'bc', 'd')]),
                          st.integers(0, 4), st.integers(0, 4),
                          st.sampled_from(['', 'base', 'base_link'])),
                min_size=1, max_size=20))
def test_the_layout_cache_reads_every_message_as_a_fresh_parse_does(layouts):
    """Same size, same names, other array lengths: the cache must not reuse a stale layout."""
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState as RosJointState
    cache, tuples_cache = JointStateNames(), JointStateNames()
    rng = np.random.default_rng(len(layouts))
    for names, n_pos, n_vel, frame in layouts:
        msg = RosJointState(name=list(names), position=rng.normal(size=n_pos).tolist(),
                            velocity=rng.normal(size=n_vel).tolist())
        msg.header.frame_id = frame
        msg.header.stamp.sec = int(rng.integers(0, 2**31))
        raw = serialize_message(msg)
        cached, fresh = parse_joint_state(raw, cache), parse_joint_state(raw)
        assert cached[:2] == fresh[:2] == (msg.header.stamp.sec * 10**9, tuple(names))
        for a, b in zip(cached[2:], fresh[2:]):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(cached[2], msg.position)
        np.testing.assert_array_equal(cached[3], msg.velocity)
        as_tuples = parse_joint_state(raw, tuples_cache, as_tuples=True)
        assert as_tuples == (cached[0], cached[1], tuple(msg.position), tuple(msg.velocity))


def joint_state_with_efforts(names, positions, velocities, efforts):
    msg = JointState(header=Header(stamp=Time(sec=1, nanosec=2), frame_id='f'),
                     name=list(names), position=np.array(positions, dtype=float),
                     velocity=np.array(velocities, dtype=float),
                     effort=np.array(efforts, dtype=float))
    return bytes(TS.serialize_cdr(msg, 'sensor_msgs/msg/JointState'))


def test_a_sequence_ending_at_the_last_byte_is_read():
    raw = joint_state_with_efforts(['a', 'b'], [1.0, 2.0], [], [5.0, 6.0])
    _, names, positions, velocities = parse_joint_state(raw)
    assert names == ('a', 'b') and positions.tolist() == [1.0, 2.0] and len(velocities) == 0


def test_same_size_messages_with_other_sequence_lengths_are_not_one_layout():
    """One velocity and two efforts, or two velocities and one effort: same size (padding)."""
    one = joint_state_with_efforts(['a', 'b'], [1.0, 2.0], [3.0], [5.0, 6.0])
    two = joint_state_with_efforts(['a', 'b'], [1.0, 2.0], [3.0, 4.0], [5.0])
    assert len(one) == len(two)
    cache = JointStateNames()
    for raw, rates in ((one, [3.0]), (two, [3.0, 4.0]), (one, [3.0])):
        _, _, positions, velocities = parse_joint_state(raw, cache)
        assert positions.tolist() == [1.0, 2.0] and velocities.tolist() == rates


@pytest.mark.parametrize('length', [0, 10**6])
def test_a_string_length_of_zero_or_past_the_end_is_malformed(length):
    raw = bytearray(joint_state_bytes(['a'], [1.0], frame_id='f'))
    raw[12:16] = length.to_bytes(4, 'little')  # the frame id's length (with its NUL)
    with pytest.raises(CdrError, match='string runs past the end'):
        parse_joint_state(bytes(raw))


def tf_message_bytes(edges, stamp=(1, 2)):
    TransformStamped = TS.types['geometry_msgs/msg/TransformStamped']
    Transform = TS.types['geometry_msgs/msg/Transform']
    Vector3 = TS.types['geometry_msgs/msg/Vector3']
    Quaternion = TS.types['geometry_msgs/msg/Quaternion']
    TFMessage = TS.types['tf2_msgs/msg/TFMessage']
    transforms = []
    for parent, child, v in edges:
        transforms.append(TransformStamped(
            header=Header(stamp=Time(sec=stamp[0], nanosec=stamp[1]), frame_id=parent),
            child_frame_id=child,
            transform=Transform(translation=Vector3(x=v[0], y=v[1], z=v[2]),
                                rotation=Quaternion(x=v[3], y=v[4], z=v[5], w=v[6]))))
    return bytes(TS.serialize_cdr(TFMessage(transforms=transforms), 'tf2_msgs/msg/TFMessage'))


def test_tf_messages_read_as_rosbags_writes_them():
    from dq_fk_ros.messages.cdr_tf import tf_layout, tf_values
    edges = [('world', 'b', (1.0, 2.0, 3.0, 0.0, 0.0, 0.6, 0.8)),
             ('b', 'odd_length', (-1.0, 0.5, 0.25, 0.6, 0.0, 0.0, 0.8)),
             ('odd_length', 'c', (0.0, 0.0, 9.0, 0.0, 1.0, 0.0, 0.0))]
    raw = tf_message_bytes(edges, stamp=(5, 7))
    layout = tf_layout(raw)
    assert layout.edges == (('world', 'b'), ('b', 'odd_length'), ('odd_length', 'c'))
    transforms, stamp = tf_values(raw, layout)
    assert transforms == [(p, c, v) for p, c, v in edges] and stamp == 5_000_000_007
    assert tf_values(tf_message_bytes([]), tf_layout(tf_message_bytes([]))) == ([], 0)
    for cut in (3, 9, 20, len(raw) - 1):
        with pytest.raises(CdrError):
            tf_layout(raw[:cut])


def test_the_newest_message_of_each_layout_is_kept():
    from dq_fk_ros.messages.cdr_tf import TfLatest
    latest = TfLatest(max_layouts=2)
    pose = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    ab = tf_message_bytes([('w', 'ab', pose)], stamp=(1, 0))
    cd = tf_message_bytes([('w', 'cd', pose)], stamp=(2, 0))  # same size, other frames
    assert len(ab) == len(cd)
    latest.take(ab)
    latest.take(cd)
    latest.take(tf_message_bytes([('w', 'ab', (1.0,) + pose[1:])], stamp=(3, 0)))
    got = sorted(latest.pop())
    assert got == [([('w', 'ab', (1.0,) + pose[1:])], 3_000_000_000),
                   ([('w', 'cd', pose)], 2_000_000_000)]
    assert latest.pop() == []
    latest.take(tf_message_bytes([('w', 'ef', pose)]))  # a third layout: the oldest goes
    latest.take(ab)
    assert sorted(t[0][0][1] for t in latest.pop()) == ['ab', 'ef']
    with pytest.raises(CdrError):
        latest.take(b'\x00\x01\x00\x00\xff\xff\xff\xff')


def test_garbage_in_alignment_padding_is_still_one_layout():
    """Padding is left unset by rclpy: only a layout's counts and strings are compared."""
    from dq_fk_ros.messages.cdr_tf import tf_layout, TfLatest
    pose = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    raw = tf_message_bytes([('w', 'xyz', pose)])
    layout = tf_layout(raw)
    (_, frame_end), (child_start, _) = layout.strings[1], layout.strings[2]
    assert child_start - frame_end == 2  # 'w' and its NUL: two bytes of padding follow
    dirty = bytearray(raw)
    dirty[frame_end:child_start] = b'\xee\xee'
    latest = TfLatest()
    latest.take(raw)
    latest.take(bytes(dirty))
    assert len(latest.pop()) == 1


def test_forgotten_layouts_and_their_messages_are_gone():
    from dq_fk_ros.messages.cdr_tf import TfLatest
    pose = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    ab1, cd1, ef1 = (tf_message_bytes([('w', n, pose)], stamp=(s, 0))
                     for n, s in (('ab', 1), ('cd', 2), ('ef', 3)))
    ab2 = tf_message_bytes([('w', 'ab', pose)], stamp=(4, 0))
    latest = TfLatest(max_layouts=2)
    for raw in (ab1, cd1, ef1, ab2):  # ef forgets ab (and ab1); ab again forgets cd
        latest.take(raw)
    assert sorted(stamp for _, stamp in latest.pop()) == [3_000_000_000, 4_000_000_000]
    many = TfLatest()  # 64 layouts by default
    for k in range(65):
        many.take(tf_message_bytes([('w', f'f{k:02d}', pose)]))
    assert sorted(t[0][0][1] for t in many.pop()) == [f'f{k:02d}' for k in range(1, 65)]


def test_a_big_endian_or_short_tf_message_is_refused_by_its_header():
    raw = bytearray(tf_message_template([('world', 'base')]).fill(
        np.array([1]), np.zeros((1, 7)))[0].tobytes())
    assert tf_layout(bytes(raw)).edges == (('world', 'base'),)
    raw[1] = 0  # big-endian CDR: long enough, the wrong header
    with pytest.raises(CdrError, match='little-endian'):
        tf_layout(bytes(raw))
    with pytest.raises(CdrError, match='little-endian'):
        tf_layout(CDR_LE_HEADER + b'\x00\x00')  # the right header, too short


def test_a_tf_frame_id_longer_than_what_is_left_is_refused():
    raw = bytearray(tf_message_template([('world', 'base')]).fill(
        np.array([1]), np.zeros((1, 7)))[0].tobytes())
    raw[16:20] = (len(raw) - 16).to_bytes(4, 'little')  # the first frame id's length
    with pytest.raises(CdrError, match='string runs past the end'):
        tf_layout(bytes(raw))


def test_a_header_without_room_for_its_frame_id_says_so():
    raw = joint_state_bytes(['a'], [1.0])[:16]  # header, stamp, frame id length: no text
    with pytest.raises(CdrError, match='string runs past the end'):
        parse_joint_state(raw)
    with pytest.raises(CdrError, match='not a little-endian CDR message'):
        parse_joint_state(raw[:15])


def test_a_tf_count_beyond_64_bytes_a_transform_is_refused_at_once():
    from dq_fk_ros.messages.cdr_tf import tf_layout
    head = b'\x00\x01\x00\x00'
    for count, words in ((5, 'string runs past the end'),  # 5 x 64 bytes fit: parsed
                         (6, 'more transforms than the message can hold')):
        raw = head + count.to_bytes(4, 'little') + bytes(312)  # 320 bytes
        with pytest.raises(CdrError, match=words):
            tf_layout(raw)


def test_one_publishers_messages_are_one_layout_whatever_their_stamps():
    from dq_fk_ros.messages.cdr_tf import TfLatest
    pose = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    latest = TfLatest()
    for sec in (1, 2, 3):
        latest.take(tf_message_bytes([('w', 'a', pose)], stamp=(sec, sec)))
    assert [stamp for _, stamp in latest.pop()] == [3_000_000_003]


def test_a_message_cut_right_after_a_string_misses_the_next_field():
    raw = joint_state_bytes(['abc'], [1.0])[:32]  # ends with the name's NUL
    with pytest.raises(CdrError, match='^message ends early'):
        parse_joint_state(raw)


def test_a_batch_of_same_size_messages_of_two_layouts():
    one = joint_state_with_efforts(['a', 'b'], [1.0, 2.0], [3.0], [5.0, 6.0])
    two = joint_state_with_efforts(['a', 'b'], [1.0, 2.0], [3.0, 4.0], [5.0])
    runs = parse_joint_states([one, two, one, two], JointStateNames())
    assert [len(r.stamps_ns) for r in runs] == [1, 1, 1, 1]
    assert [r.velocities.tolist() for r in runs] == [[[3.0]], [[3.0, 4.0]], [[3.0]],
                                                     [[3.0, 4.0]]]


def test_a_layout_is_kept_whatever_the_padding_bytes_hold():
    """CDR padding is undefined (rclpy's holds garbage): tiago's layout was rebuilt per message."""
    names = ['a', 'bb', 'ccc', 'dddd']
    raw = bytearray(joint_state_bytes(names, [1.0, 2.0, 3.0, 4.0]))
    cache = JointStateNames()
    parse_joint_state(bytes(raw), cache)
    layout = cache.layout
    pads = [17, 18, 19]  # after the empty frame id ('' + NUL: 1 byte, then 3 of padding)
    for at in pads:
        raw[at] = 0xAB
    at = layout.positions[0] + 3 * 8
    raw[at:at + 8] = struct.pack('<d', 9.0)  # and a new value
    stamp, got, positions, _ = parse_joint_state(bytes(raw), cache)
    assert cache.layout is layout and got == tuple(names) and positions[-1] == 9.0
    renamed = bytearray(raw)
    at = bytes(raw).index(b'bb\x00')
    renamed[at:at + 2] = b'xy'  # a name of the same length, the same padding
    _, got, _, _ = parse_joint_state(bytes(renamed), cache)
    assert got == ('a', 'xy', 'ccc', 'dddd') and cache.layout is not layout


def test_a_batch_with_undefined_padding_is_one_run():
    """Recorded messages differ in their padding: each was a layout of its own in a bag."""
    names = ['a', 'bb', 'ccc']
    raws = []
    for k in range(20):
        raw = bytearray(joint_state_bytes(names, [k, 2.0 * k, 3.0], stamp_ns=k))
        raw[17:20] = bytes([k, k + 1, k + 2])  # the padding after the empty frame id
        raws.append(bytes(raw))
    runs = parse_joint_states(raws)
    assert len(runs) == 1 and runs[0].names == tuple(names)
    np.testing.assert_array_equal(runs[0].positions[:, 1], 2.0 * np.arange(20))
    renamed = raws[:5] + [raws[5].replace(b'bb\x00', b'xy\x00')] + raws[6:]
    runs = parse_joint_states(renamed)
    assert [r.names for r in runs] == [tuple(names), ('a', 'xy', 'ccc'), tuple(names)]


@settings(max_examples=40)
@given(st.integers(17, 60), st.data())
def test_tf_latest_tells_layouts_apart(count, data):
    """A big robot's layout (one numpy gather) and run by run decide alike, padding aside."""
    from dq_fk_ros.messages.cdr_tf import (_compiled_check, _is_layout, _layout_check, tf_layout,
                                           tf_values, TfLatest)
    pose = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    edges = [(f'p{k % 5}', f'child_{k}', pose) for k in range(count)]
    raw = tf_message_bytes(edges, stamp=(1, 0))
    layout = tf_layout(raw)
    runs, gather = _layout_check(layout)
    assert gather is not None and len(runs) > 16
    k = data.draw(st.integers(0, count - 1))
    renamed = list(edges)
    renamed[k] = (edges[k][0], f'child_{k}'[:-1] + '#', pose)  # same size, one byte off
    other = tf_message_bytes(renamed, stamp=(2, 0))
    dirty = bytearray(tf_message_bytes(edges, stamp=(3, 0)))
    noise = random.Random(data.draw(st.integers(0, 2**32)))
    for (_, end), (start, _) in zip(layout.strings, layout.strings[1:]):
        dirty[end:start] = noise.randbytes(start - end)  # stamps, padding, values
    compiled = _compiled_check((runs, gather))
    for message, same in ((raw, True), (other, False), (bytes(dirty), True)):
        assert len(message) == len(raw)
        assert _is_layout(message, (runs, gather)) is same
        assert _is_layout(message, (runs, None)) is same
        if compiled is not None:  # the C check: the same, and nothing past the end read
            assert compiled.match(message) is same
            assert compiled.match(message[:-1]) is same   # (the last values are not read)
            assert compiled.match(message[:layout.strings[-1][1] - 1]) is False
    latest = TfLatest()
    for message in (raw, other, bytes(dirty)):
        latest.take(message)
    got = latest.pop()  # the newest of each: the dirty one stands for the first layout
    shown = [repr(values) for values in got]  # (the noise may hold NaN: compared as text)
    assert len(got) == 2 and repr(tf_values(bytes(dirty), layout)) in shown
    assert repr(tf_values(other, tf_layout(other))) in shown


@given(st.text(max_size=40), st.integers(-2**31, 2**31 - 1), st.integers(0, 2**32 - 1),
       st.lists(st.floats(allow_nan=False), min_size=7, max_size=7))
def test_pose_stamped_reads_as_rosbags_reads_it(frame_id, sec, nanosec, values):
    from dq_fk_ros.messages.cdr_tf import parse_pose_stamped
    msgs = TS.types
    pose = msgs['geometry_msgs/msg/Pose'](
        position=msgs['geometry_msgs/msg/Point'](*values[:3]),
        orientation=msgs['geometry_msgs/msg/Quaternion'](*values[3:]))
    header = msgs['std_msgs/msg/Header'](
        stamp=msgs['builtin_interfaces/msg/Time'](sec, nanosec), frame_id=frame_id)
    raw = bytes(TS.serialize_cdr(msgs['geometry_msgs/msg/PoseStamped'](header, pose),
                                 'geometry_msgs/msg/PoseStamped'))
    assert parse_pose_stamped(raw) == (sec * 1_000_000_000 + nanosec, frame_id, tuple(values))
    for cut in (3, 15, len(raw) - 1):
        with pytest.raises(CdrError):
            parse_pose_stamped(raw[:cut])
    with pytest.raises(CdrError):
        parse_pose_stamped(raw + b'\x00' * 8)  # not a PoseStamped of this size
    with pytest.raises(CdrError):
        parse_pose_stamped(raw[:1] + b'\x00' + raw[2:])  # big-endian


def test_a_pose_stamped_of_no_sense_is_refused_in_one_line():
    from dq_fk_ros.messages.cdr_tf import parse_pose_stamped
    header = CDR_LE_HEADER + b'\x00' * 8
    for raw in (header + b'\xff\xff\xff\xff' + b'\x00' * 60,   # a frame id past the end
                header + b'\x02\x00\x00\x00\xff\x00' + b'\x00' * 58,  # not UTF-8
                header + b'\x00' * 4 + b'\x00' * 60,             # a string of length 0
                b'\x00' * 5000):
        with pytest.raises(CdrError) as error:
            parse_pose_stamped(raw)
        assert '\n' not in str(error.value)


@settings(max_examples=60)
@given(st.lists(st.text('abcj_0123', min_size=1, max_size=9), min_size=1, max_size=6,
                unique=True), st.booleans(), st.text('xyz', max_size=7), st.data())
def test_the_compiled_batch_match_is_the_numpy_compare(names, with_velocities, frame_id, data):
    """_Layout.matches: a memcmp per run in C, the numpy compare its reference; spans anywhere."""
    from dq_fk_ros.messages.cdr import _Layout, _rows, COMPILED
    n = len(names)
    raw = joint_state_bytes(names, [0.5] * n, [0.25] * n if with_velocities else [], 7,
                            frame_id)
    layout = _Layout(raw, JointStateNames())
    noise = random.Random(data.draw(st.integers(0, 2**32)))
    messages = []
    for _ in range(data.draw(st.integers(1, 12))):
        message = bytearray(joint_state_bytes(names, [noise.uniform(-3, 3)] * n,
                                              [1.0] * n if with_velocities else [],
                                              noise.randrange(10**12), frame_id))
        kind = data.draw(st.sampled_from(['same', 'flip', 'short', 'long']))
        if kind == 'flip':  # any byte: a fixed one (another layout) or a value (the same)
            message[noise.randrange(len(message))] ^= 1 << noise.randrange(8)
        elif kind == 'short':
            message = message[:noise.randrange(len(message))]
        elif kind == 'long':
            message += b'\0' * noise.randint(1, 9)
        messages.append(bytes(message))
    # back to back with gaps between them, as records lie in a chunk
    joined, starts = bytearray(), []
    for message in messages:
        joined += noise.randbytes(noise.randrange(4))
        starts.append(len(joined))
        joined += message
    joined = np.frombuffer(bytes(joined), np.uint8)
    starts = np.array(starts, np.int64)
    lengths = np.array([len(m) for m in messages], np.int64)
    same = np.flatnonzero(lengths == layout.size)
    expected = np.zeros(len(messages), bool)
    if len(same):  # the reference sees only messages of the layout's size
        rows = _rows(joined, starts, same, layout.size)
        expected[same] = (rows[:, layout.fixed] == layout.template).all(axis=1)
    # and the reference is right: a message of the same fixed bytes is one of the layout
    for i, message in enumerate(messages):
        assert expected[i] == (len(message) == layout.size and all(
            message[k] == raw[k] for k in layout.fixed))
    if COMPILED is None:
        return
    got = np.frombuffer(layout.runs.match_many(joined, starts, lengths, layout.size), bool)
    assert got.tolist() == expected.tolist()
    with pytest.raises(ValueError, match='outside the buffer'):
        layout.runs.match_many(joined, starts + len(joined) + 1, lengths, layout.size)


@settings(max_examples=60)
@given(st.lists(st.tuples(st.text(min_size=1, max_size=9), st.text(min_size=1, max_size=9),
                          st.integers(-2**31, 2**31 - 1), st.integers(0, 10**9 - 1),
                          st.tuples(*[st.floats(allow_nan=False)] * 7)), max_size=6))
def test_tf_reader_reads_as_rosbags_reads_it(transforms):
    """Each transform's own stamp and values, as rosbags deserializes the same bytes."""
    from dq_fk_ros.messages.cdr_tf import TfReader
    TransformStamped = TS.types['geometry_msgs/msg/TransformStamped']
    Transform = TS.types['geometry_msgs/msg/Transform']
    Vector3 = TS.types['geometry_msgs/msg/Vector3']
    Quaternion = TS.types['geometry_msgs/msg/Quaternion']
    message = TS.types['tf2_msgs/msg/TFMessage'](transforms=[TransformStamped(
        header=Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=parent),
        child_frame_id=child,
        transform=Transform(translation=Vector3(x=v[0], y=v[1], z=v[2]),
                            rotation=Quaternion(x=v[3], y=v[4], z=v[5], w=v[6])))
        for parent, child, sec, nanosec, v in transforms])
    raw = bytes(TS.serialize_cdr(message, 'tf2_msgs/msg/TFMessage'))
    back = TS.deserialize_cdr(raw, 'tf2_msgs/msg/TFMessage')
    expected = [(t.header.frame_id, t.child_frame_id,
                 t.header.stamp.sec * 10**9 + t.header.stamp.nanosec,
                 (t.transform.translation.x, t.transform.translation.y,
                  t.transform.translation.z, t.transform.rotation.x, t.transform.rotation.y,
                  t.transform.rotation.z, t.transform.rotation.w)) for t in back.transforms]
    reader = TfReader()
    assert reader.read(raw) == expected
    assert reader.read(raw) == expected    # the second time from the layout it keeps
    with pytest.raises(CdrError):
        reader.read(raw[:len(raw) // 2] if transforms else b'\x01\x00')


def test_a_batch_is_one_run_whatever_the_bytes_of_its_values():
    """Values right after their count (no padding between) are not part of the layout."""
    raws = [joint_state_bytes(['a'], [1.0 + k * 2.0 ** -52], [k * 2.0 ** -40]) for k in range(4)]
    assert raws[0][36] != raws[1][36]   # position 0's first byte follows its count at 32
    runs = parse_joint_states(raws)
    assert len(runs) == 1
    assert runs[0].positions[:, 0].tolist() == [1.0 + k * 2.0 ** -52 for k in range(4)]
    assert runs[0].velocities[:, 0].tolist() == [k * 2.0 ** -40 for k in range(4)]


def test_a_batch_reads_each_messages_header_not_the_first_ones():
    good = joint_state_bytes(['a', 'b'], [1.0, 2.0])
    for at, value in ((0, 7), (1, 0)):   # not plain CDR, or big-endian: the same size
        broken = bytearray(good)
        broken[at] = value
        out = parse_joint_states([good, bytes(broken), good])
        kinds = [type(r).__name__ for r in out]
        assert kinds == ['JointStateRun', 'MalformedJointState', 'JointStateRun'], (at, kinds)


def test_a_batch_reuses_the_names_of_the_cache_while_their_bytes_are_the_same():
    cache = JointStateNames()
    first = parse_joint_states([joint_state_bytes(['a', 'b'], [1.0, 2.0])], cache)
    again = parse_joint_states([joint_state_bytes(['a', 'b'], [3.0, 4.0])], cache)
    assert again[0].names is first[0].names == ('a', 'b')


@pytest.mark.parametrize('starts, lengths', [([-1], [10]), ([0], [-1]), ([0, 40], [20, 20]),
                                             ([60], [1])])
def test_a_span_outside_the_buffer_is_refused_in_one_line(starts, lengths):
    joined = joint_state_bytes(['a'], [1.0])   # 52 bytes
    assert len(joined) == 52
    with pytest.raises(ValueError, match='^a message span lies outside the buffer$'):
        group_joint_state_spans(joined, starts, lengths)


def test_at_most_eight_layouts_are_matched_against_the_whole_batch(monkeypatch):
    """Each further layout is read for its one message: the work stays bounded."""
    from dq_fk_ros.messages import cdr
    sizes = []
    matches = cdr._Layout.matches

    def counting(self, joined, starts, lengths, rows):
        sizes.append(len(starts))
        return matches(self, joined, starts, lengths, rows)
    monkeypatch.setattr(cdr._Layout, 'matches', counting)
    names = [f'n{k}' for k in range(12)]   # twelve layouts of one size, twice each
    raws = [joint_state_bytes([name], [float(k)]) for k in range(2) for name in names]
    assert len({len(r) for r in raws}) == 1
    runs = parse_joint_states(raws)
    assert [r.names for r in runs] == [(name,) for name in names] * 2
    assert sizes == [24 - 2 * k for k in range(8)] + [1] * 8   # 8 of the batch, then one each
    joined = b''.join(raws)
    starts, lengths = np.arange(24) * len(raws[0]), np.full(24, len(raws[0]))
    for call in (lambda: cdr.parse_joint_state_spans(joined, starts, lengths),
                 lambda: cdr.group_joint_state_spans(joined, starts, lengths)):
        sizes.clear()
        call()
        assert sizes == [24 - 2 * k for k in range(8)] + [1] * 8, call
    sizes.clear()
    parse_joint_states(raws, max_layouts=2)
    assert sizes == [24, 22] + [1] * 20


def test_a_cached_layout_is_not_reused_for_another_name_count_behind_other_padding():
    """Padding bytes differ, so the strings are compared one by one: the name count too."""
    first = joint_state_bytes(['ab'], [1.0, 2.0], [], frame_id='f')
    count_at = 4 + 8 + 4 + 2 + 2   # header, stamp, frame id's length and 'f\0', padding
    assert struct.unpack_from('<I', first, count_at) == (1,)
    other = bytearray(first)
    other[count_at - 1] = 0x55                    # another serializer's padding
    struct.pack_into('<I', other, count_at, 2)    # and two names
    cache = JointStateNames()
    parse_joint_state(first, cache)
    try:
        fresh = parse_joint_state(bytes(other))
    except CdrError as exc:
        with pytest.raises(CdrError, match=re.escape(str(exc))):
            parse_joint_state(bytes(other), cache)
    else:
        assert parse_joint_state(bytes(other), cache)[1] == fresh[1]


def test_rows_are_the_messages_asked_for_a_view_where_all_of_them_abut():
    from dq_fk_ros.messages.cdr import _rows
    joined = np.arange(12, dtype=np.uint8)
    starts = np.array([0, 4, 8])
    every = _rows(joined, starts, np.array([0, 1, 2]), 4)
    np.testing.assert_array_equal(every, joined.reshape(3, 4))
    assert np.shares_memory(every, joined)        # abutting, to the last byte: no copy
    some = _rows(joined, starts, np.array([0, 2]), 4)
    np.testing.assert_array_equal(some, [[0, 1, 2, 3], [8, 9, 10, 11]])
    apart = _rows(np.arange(14, dtype=np.uint8), np.array([0, 5, 10]), np.array([0, 1, 2]), 4)
    np.testing.assert_array_equal(apart, [[0, 1, 2, 3], [5, 6, 7, 8], [10, 11, 12, 13]])
