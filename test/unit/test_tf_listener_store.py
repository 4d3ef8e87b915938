"""The listener's fast store (Buffer.append_raw, _tf.append_many) against set_transform."""

import math

from dq_fk_ros.messages.cdr_tf import MAX_REMEMBERED_NAME_BYTES, TfReader
from dq_fk_ros.ros.tf_buffer import Buffer, MAX_PLANS, SLICE
from dq_fk_ros.transforms.buffer_core import COMPILED, MAX_FRAME_ID
from geometry_msgs.msg import TransformStamped
from hypothesis import given, settings, strategies as st
import pytest
from rclpy.duration import Duration
from rclpy.serialization import serialize_message
from tf2_msgs.msg import TFMessage

S = 10**9
ONE = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)


def message(transforms):
    msg = TFMessage()
    for parent, child, stamp, pose in transforms:
        t = TransformStamped()
        t.header.frame_id, t.child_frame_id = parent, child
        t.header.stamp.sec, t.header.stamp.nanosec = divmod(stamp, S)
        tr, r = t.transform.translation, t.transform.rotation
        tr.x, tr.y, tr.z, r.x, r.y, r.z, r.w = pose
        msg.transforms.append(t)
    return serialize_message(msg)


def state(buffer):
    core = buffer.core
    return (core.names, {k: core.authority.get(k) for k in range(len(core.names))},
            [None if c is None else (c.static, c.parent, c.values) if c.static else
             (list(c.stamps[c.start:c.count]), list(c.parents[c.start:c.count]),
              list(c.values[7 * c.start:7 * c.count]))
             for c in core.caches])


POSES = st.sampled_from([(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0), (1.0, 2.0, 3.0, 0.0, 0.0, 0.6, 0.8),
                         (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.004), (math.nan, 0, 0, 0, 0, 0, 1.0),
                         (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.5), (math.inf, 0, 0, 0, 0, 0, 1.0)])
FRAMES = st.sampled_from(['a', 'b', 'c', '/c', 'd', ''])


@settings(max_examples=150, deadline=None)
@given(st.lists(st.lists(st.tuples(FRAMES, FRAMES, st.integers(0, 40), POSES),
                         min_size=1, max_size=4), min_size=1, max_size=30),
       st.sampled_from([5, 10**3]))
def test_the_listener_stores_what_set_transform_stores(messages, cache_steps):
    if COMPILED is None:
        pytest.fail('transforms/_tf is not built (make setup builds it)')
    fast = Buffer(cache_time=Duration(nanoseconds=cache_steps * S // 4))
    slow = Buffer(cache_time=Duration(nanoseconds=cache_steps * S // 4))
    reader, plans = TfReader(), {}
    for transforms in messages:
        raw = message([(p, c, t * S // 4, pose) for p, c, t, pose in transforms])
        taken = fast.append_raw(raw, reader.layout(raw), plans, 'x')
        assert taken == slow.set_raw(TfReader.unpack(raw, reader.layout(raw)), 'x')
    assert state(fast) == state(slow)


def test_compaction_and_pruning_over_many_messages():
    """Samples pruned past the cache time and the arrays compacted, as the reference does."""
    fast = Buffer(cache_time=Duration(seconds=1))
    slow = Buffer(cache_time=Duration(seconds=1))
    reader, plans = TfReader(), {}
    for k in range(12_000):
        raw = message([('world', 'base', k * S // 1000, (k, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))])
        fast.append_raw(raw, reader.layout(raw), plans, 'x')
        slow.set_raw(TfReader.unpack(raw, reader.layout(raw)), 'x')
    assert state(fast) == state(slow)
    cache = fast.core.caches[fast.core.ids['base']]
    # tf2 prunes by the newest before each insert: 1 s of samples and the one just added
    assert len(cache) == 1002 and cache.count < 6000   # compacted


def test_a_message_longer_than_a_slice_is_stored_as_set_transform_stores_it():
    # the lock is taken a slice at a time: the slices' seams must not change what is stored
    fast, slow = Buffer(), Buffer()
    reader, plans = TfReader(), {}
    assert SLICE < 600
    for k in range(3):
        raw = message([('world', f'f{j % 300}', (k * 2 + j // 300) * S,
                        (float(j),) + ONE[1:]) for j in range(600)])
        taken = fast.append_raw(raw, reader.layout(raw), plans, 'x')
        assert taken == slow.set_raw(TfReader.unpack(raw, reader.layout(raw)), 'x') == 600
    assert state(fast) == state(slow)


def test_what_a_listener_remembers_is_bounded_whatever_the_names():
    # 10 000 names of 50 KB had held a listener at 1 GiB: names are refused past
    # MAX_FRAME_ID, layouts remembered without their message and only up to a size, plans
    # at most MAX_PLANS
    buffer, reader, plans = Buffer(), TfReader(), {}
    huge = 'n' * 50_000
    for k in range(100):
        raw = message([('world', huge + str(k), S, ONE),
                       ('world', f'small_{k}', S, ONE)])
        layout = reader.layout(raw)
        assert buffer.append_raw(raw, layout, plans, 'x') == 1
    assert buffer.core.refused == {'TF_LONG_FRAME_ID': 100}
    assert all(len(name) <= MAX_FRAME_ID for name in buffer.core.frame_names())
    assert len(plans) <= MAX_PLANS
    remembered = reader._layouts._order
    assert len(remembered) <= 64 and all(known.layout.raw == b'' for known in remembered)
    assert sum(known.name_bytes for known in remembered) <= 64 * MAX_REMEMBERED_NAME_BYTES
    big = message([('world', 'x' * 1000 + str(j), S, ONE)
                   for j in range(300)])
    reader.layout(big)
    assert len(reader._layouts._order) == len(remembered)   # (300 KB of names: not kept)
