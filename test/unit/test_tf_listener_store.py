"""The listener's fast store (Buffer.append_raw, _tf.append_many) against set_transform."""

import math

from dq_fk_ros.messages.cdr_tf import TfReader
from dq_fk_ros.ros.tf_buffer import Buffer
from dq_fk_ros.transforms.buffer_core import COMPILED
from geometry_msgs.msg import TransformStamped
from hypothesis import given, settings, strategies as st
import pytest
from rclpy.duration import Duration
from rclpy.serialization import serialize_message
from tf2_msgs.msg import TFMessage

S = 10**9


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
