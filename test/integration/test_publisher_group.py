"""
dq_fk_ros.ros.publisher_group: many publishers in one call, rcl from C beside publish_raw.

The compiled group (``_rcl_publish.Publishers``) is held equal to its reference, each
publisher's ``publish_raw``: a subscriber receives the same bytes, in the same order, from
both. It holds rclpy's handles: a publisher destroyed meanwhile goes only once the group lets
go. No Python value crashes it (a hypothesis fuzz; ``make sanitize`` runs this file under
ASan and UBSan).
"""

import time

from dq_fk_ros.ros.publisher_group import COMPILED, PublisherGroup
from dq_fk_ros.testing import wait_for_match
from geometry_msgs.msg import PoseStamped
from hypothesis import given, strategies as st
import pytest
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from ros_harness import own_node

pytestmark = pytest.mark.integration
needs_c = pytest.mark.skipif(not COMPILED, reason='dq_fk_ros.ros._rcl_publish is not built '
                             '(no rcl headers at install, or DQ_FK_PURE_PYTHON): the '
                             'publish_raw path runs, tested by the other cases')
QOS = QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE)
ALLOWED = (ValueError, TypeError, OverflowError, MemoryError, RuntimeError)


@pytest.fixture
def node(ros_domain_id):
    with own_node('dq_fk_test_publisher_group') as node:
        yield node


def pose_bytes(x, frame='world'):
    msg = PoseStamped()
    msg.header.frame_id = frame
    msg.header.stamp.sec = 7
    msg.pose.position.x = float(x)
    msg.pose.orientation.w = 1.0
    return serialize_message(msg)


def received(node, topics, compiled, updates):
    """Publish ``updates`` (lists of bytes) on ``topics`` by a group; return what arrived."""
    pubs = [node.create_publisher(PoseStamped, t, QOS) for t in topics]
    got = {t: [] for t in topics}
    subs = [node.create_subscription(PoseStamped, t, got[t].append, QOS, raw=True)
            for t in topics]
    executor = rclpy.executors.SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    group = PublisherGroup(pubs, compiled=compiled)
    try:
        assert group.compiled == (compiled and COMPILED)
        for pub, sub in zip(pubs, subs):
            wait_for_match(pub, sub)
        for messages in updates:
            group.publish(messages)
        deadline = time.monotonic() + 10.0
        while sum(map(len, got.values())) < len(updates) * len(topics) and \
                time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
    finally:
        group.close()
        executor.remove_node(node)
        executor.shutdown()
        for s in subs:
            node.destroy_subscription(s)
        for p in pubs:
            node.destroy_publisher(p)
    return got


@needs_c
def test_rcl_from_c_delivers_what_publish_raw_delivers(node):
    topics = [f'/dq_fk_test_group/c{i}' for i in range(6)]
    # (rclpy's serializer leaves padding bytes unset: the same bytes objects go to both)
    updates = [[pose_bytes(100 * r + i, f'f{i}') for i in range(6)] for r in range(5)]
    by_c = received(node, topics, True, updates)
    by_raw = received(node, [t.replace('/c', '/raw') for t in topics], False, updates)
    assert list(by_c.values()) == list(by_raw.values())
    # each topic got its own messages, in order, byte for byte
    for i, t in enumerate(topics):
        assert by_c[t] == [update[i] for update in updates]
        assert [deserialize_message(b, PoseStamped).pose.position.x for b in by_c[t]] == \
            [100.0 * r + i for r in range(5)]


def test_a_closed_group_is_regrouped_even_for_the_same_publishers(node):
    pubs = [node.create_publisher(PoseStamped, '/dq_fk_test_group/re', QOS)]
    group = PublisherGroup(pubs)
    assert group.regroup(list(pubs)) is group
    group.close()
    again = group.regroup([])
    assert again is not group and not again.closed and len(again) == 0
    again.publish([])  # nothing to publish: no error
    assert again.regroup(pubs) is not again and again.closed
    group.close()


def test_publish_raw_group_checks_the_count(node):
    pubs = [node.create_publisher(PoseStamped, f'/dq_fk_test_group/n{i}', QOS) for i in range(2)]
    group = PublisherGroup(pubs, compiled=False)
    with pytest.raises(ValueError, match='3 messages for 2 publishers'):
        group.publish([b'', b'', b''])
    group.close()
    assert len(group) == 0


@needs_c
def test_a_destroyed_publisher_lives_until_the_group_lets_go(node):
    pub = node.create_publisher(PoseStamped, '/dq_fk_test_group/held', QOS)
    handle = pub.handle
    group = PublisherGroup([pub])
    node.destroy_publisher(pub)
    assert handle.pointer != 0  # asked to go, still held: publishing is safe
    group.publish([pose_bytes(1)])
    group.close()
    assert handle.pointer == 0  # destroyed when let go
    with pytest.raises(ValueError, match='closed'):
        group.publish([pose_bytes(1)])
    group.close()  # idempotent
    # a handle already asked to go cannot be taken
    with pytest.raises(Exception, match='destruction was requested'):
        PublisherGroup([pub])


@needs_c
def test_a_shut_down_context_is_an_error_not_a_crash(ros_domain_id):
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('dq_fk_test_publisher_group_shutdown', context=context)
    pub = node.create_publisher(PoseStamped, '/dq_fk_test_group/shutdown', QOS)
    group = PublisherGroup([pub])
    group.publish([pose_bytes(1)])
    rclpy.shutdown(context=context)
    with pytest.raises(RuntimeError, match='message 0'):
        group.publish([pose_bytes(2)])
    group.close()
    node.destroy_node()


VALUES = st.one_of(st.none(), st.integers(), st.floats(), st.text(max_size=4),
                   st.binary(max_size=64), st.just(object()), st.just(int),
                   st.just(2**64), st.just(-1), st.lists(st.binary(max_size=8), max_size=4))


@pytest.fixture(scope='module')
def fuzz_handles(ros_domain_id):
    """Three publishers' handles, one node for every example of the fuzz."""
    with own_node('dq_fk_test_publisher_group_fuzz') as node:
        yield [node.create_publisher(PoseStamped, f'/dq_fk_test_group/z{i}', QOS).handle
               for i in range(3)]


@needs_c
@given(data=st.data())
def test_the_compiled_group_survives_any_arguments(fuzz_handles, data):
    from dq_fk_ros.ros._rcl_publish import Publishers
    handles = fuzz_handles
    made = data.draw(st.one_of(
        VALUES, st.lists(st.one_of(st.sampled_from(handles), VALUES), max_size=4),
        st.lists(st.sampled_from(handles), max_size=4).map(tuple)))
    try:
        group = Publishers(made)
    except ALLOWED:
        group = Publishers(handles)
    messages = data.draw(st.one_of(
        VALUES, st.lists(st.one_of(st.binary(max_size=200), VALUES), min_size=len(group),
                         max_size=len(group)),
        st.tuples(*[st.binary(max_size=200)] * len(group))))
    try:
        group.publish(messages)
    except ALLOWED:
        pass
    if data.draw(st.booleans()):
        group.close()
        with pytest.raises(ValueError):
            group.publish(messages)
    del group  # an open group lets go when it goes
    assert all(h.pointer != 0 for h in handles)
