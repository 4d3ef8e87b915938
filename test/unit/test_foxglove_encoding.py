"""
Foxglove messages encoded from the ROS bytes (viewers/foxglove_encoding.py) against the references.

``FrameTransformsEncoder`` against the SDK's own ``foxglove.FrameTransforms`` objects and
encoder (``foxglove_feed.frame_transforms``), both decoded with google.protobuf from the
schema the SDK advertises; ``joint_state_json`` against ``json.dumps`` of the fields;
``varint`` against protobuf's own encoder.
"""

import json
import math

from dq_fk_ros.messages.cdr_templates import tf_message_template
from dq_fk_ros.messages.cdr_tf import tf_layout, tf_values
from dq_fk_ros.viewers.foxglove_encoding import FrameTransformsEncoder, joint_state_json, varint
from hypothesis import given, strategies as st
import numpy as np
import pytest

foxglove = pytest.importorskip('foxglove')


def frame_transforms_class():
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
    schema = foxglove.messages.FrameTransforms.get_schema()
    pool = descriptor_pool.DescriptorPool()
    for file in descriptor_pb2.FileDescriptorSet.FromString(schema.data).file:
        pool.Add(file)
    return message_factory.GetMessageClass(
        pool.FindMessageTypeByName('foxglove.FrameTransforms'))


FRAMES = frame_transforms_class()
NAMES = st.text(st.characters(blacklist_categories=('Cs',), blacklist_characters='\x00'),
                max_size=140)


@given(edges=st.lists(st.tuples(NAMES, NAMES), max_size=12),
       stamp=st.one_of(st.integers(0, 2**31 * 10**9), st.sampled_from(
           [0, 1, 127, 128, 10**9, 10**9 - 1, 1_700_000_000_123_456_789, 2**31 * 10**9 - 1])),
       seed=st.integers(0, 2**32 - 1))
def test_frame_transforms_decode_as_the_sdks_own(edges, stamp, seed):
    from dq_fk_ros.viewers.foxglove_feed import frame_transforms
    values = np.random.default_rng(seed).normal(size=(1, 7 * len(edges)))
    values[0, ::5] = 0.0   # zeros: fields the SDK leaves out, this encoder writes
    raw = tf_message_template(edges).fill(np.array([stamp]), values)[0].tobytes()
    layout = tf_layout(raw)
    encoder = FrameTransformsEncoder(layout)
    transforms, _ = tf_values(raw, layout)
    reference = frame_transforms(foxglove.messages,
                                 [(p, c, pose, stamp) for p, c, pose in transforms]).encode()
    ours = FRAMES.FromString(encoder.encode(raw, stamp))
    assert ours == FRAMES.FromString(reference)
    assert len(ours.transforms) == len(edges)
    # the same encoder again, another stamp length and other values (its cached forms)
    raw2 = tf_message_template(edges).fill(np.array([stamp // 7 + 3]), values[:, ::-1].copy())
    transforms2, _ = tf_values(raw2[0].tobytes(), layout)
    again = frame_transforms(foxglove.messages, [(p, c, pose, stamp // 7 + 3)
                                                 for p, c, pose in transforms2]).encode()
    assert FRAMES.FromString(encoder.encode(raw2[0].tobytes(), stamp // 7 + 3)) == \
        FRAMES.FromString(again)


def test_a_stamp_before_1970_is_refused_as_the_sdk_refuses_it():
    raw = tf_message_template([('a', 'b')]).fill(np.array([-1]), np.zeros((1, 7)))[0]
    with pytest.raises(OverflowError):
        FrameTransformsEncoder(tf_layout(raw.tobytes())).encode(raw.tobytes(), -1)
    with pytest.raises(OverflowError):
        foxglove.messages.Timestamp(-1, 0)


@given(st.integers(0, 2**64 - 1))
def test_varints_are_protobufs(value):
    from google.protobuf.internal.encoder import _VarintBytes
    assert varint(value) == _VarintBytes(value)


FLOATS = st.floats(allow_nan=True, allow_infinity=True)


@given(names=st.lists(NAMES, max_size=8), stamp=st.integers(0, 2**62),
       positions=st.lists(FLOATS, max_size=8), velocities=st.lists(FLOATS, max_size=8))
def test_joint_state_json_is_the_fields_with_null_for_what_is_not_finite(
        names, stamp, positions, velocities):
    def finite(values):
        return [v if math.isfinite(v) else None for v in values]
    sec, nanosec = divmod(stamp, 1_000_000_000)
    expected = {'header': {'stamp': {'sec': sec, 'nanosec': nanosec}, 'frame_id': ''},
                'name': names, 'position': finite(positions), 'velocity': finite(velocities)}
    text = joint_state_json(stamp, names, np.array(positions, dtype=float),
                            np.array(velocities, dtype=float))
    assert json.loads(text) == json.loads(json.dumps(expected))
    assert joint_state_json(stamp, names, positions, velocities, json.dumps(names)) == text


def test_a_huge_tf_goes_by_the_sdk_and_keeps_no_template():
    from dq_fk_ros.description.meshes import MeshAssets
    from dq_fk_ros.description.packages import PackageResolver
    from dq_fk_ros.viewers.foxglove_encoding import MAX_TEMPLATED_BYTES
    from dq_fk_ros.viewers.foxglove_feed import FoxgloveFeed
    feed = FoxgloveFeed(foxglove, MeshAssets(PackageResolver({}), []), print)
    edges = [(f'parent_{k}', f'child_{k}') for k in range(3000)]
    stamp = 1_700_000_000_000_000_001
    raw = tf_message_template(edges).fill(np.array([stamp]), np.ones((1, 7 * 3000)))[0]
    assert len(raw) > MAX_TEMPLATED_BYTES
    small = tf_message_template(edges[:2]).fill(np.array([stamp]), np.ones((1, 14)))[0]
    for message in (raw.tobytes(), small.tobytes()):
        layout = tf_layout(message)
        got = FRAMES.FromString(feed._frame_transforms(layout, message))
        assert len(got.transforms) == len(layout.edges)
        assert got.transforms[-1].timestamp.nanos == 1
    assert len(feed._encoders) == 1   # the small one's template only


def test_a_bad_static_transform_is_dropped_alone_and_a_huge_description_not_relayed():
    from dq_fk_ros.description.meshes import MeshAssets
    from dq_fk_ros.description.packages import PackageResolver
    from dq_fk_ros.description.urdf_reader import MAX_URDF_BYTES
    from dq_fk_ros.viewers.foxglove_feed import FoxgloveFeed
    lines = []
    feed = FoxgloveFeed(foxglove, MeshAssets(PackageResolver({}), []), lines.append)
    good = (0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    feed.take_static([('world', 'a', good, 1_700_000_000_000_000_000),
                      ('world', 'before_1970', good, -1),
                      ('world', 'nan', (float('nan'),) + good[1:], 5),
                      ('world', 'b', good, 0)])
    assert sorted(feed.static) == ['a', 'b'] and feed.counts['bad_static'] == 2
    feed.flush()   # the good ones are sent: no exception, no count of a failed log
    assert feed.counts['bad_input'] == 0
    huge = '<robot name="r">' + ' ' * MAX_URDF_BYTES + '</robot>'
    for _ in range(3):
        feed.take_description(huge)
    assert feed.urdf is None and feed.counts['bad_input'] == 3
    assert len(lines) == 1 and 'not relayed' in lines[0] and len(lines[0]) < 200


def test_toggled_subscriptions_resend_a_kept_message_at_most_once_a_second(monkeypatch):
    from dq_fk_ros.description.meshes import MeshAssets
    from dq_fk_ros.description.packages import PackageResolver
    from dq_fk_ros.viewers import foxglove_feed
    feed = foxglove_feed.FoxgloveFeed(foxglove, MeshAssets(PackageResolver({}), []), print)
    sent = []
    feed.description = type('Sent', (), {'log': staticmethod(sent.append)})()
    clock = [1000.0]
    monkeypatch.setattr(foxglove_feed.time, 'monotonic', lambda: clock[0])
    feed.take_description('<robot name="r"><link name="l"/></robot>')
    feed.flush()
    assert len(sent) == 1   # the new description itself
    for _ in range(50):     # a client toggling its subscription at every flush (50 Hz, 1 s)
        feed.subscribed('/robot_description')
        clock[0] += 0.02
        feed.flush()
    assert len(sent) == 2, len(sent)   # 50 before: the URDF to every client at each flush
    clock[0] += 1.0
    feed.flush()            # the last toggle's subscriber still gets it, a second later
    assert len(sent) == 3
