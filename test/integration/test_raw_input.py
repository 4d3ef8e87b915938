"""dq_fk_ros.ros.raw_input: serialized messages in and out, over DDS (loopback)."""

import os
import sys
import time

from dq_fk_ros.ros.raw_input import raw_publisher, RawSubscriptionThread, take_queued
from dq_fk_ros.testing import wait_for_match, wait_until
import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from ros_harness import own_node
from std_msgs.msg import String

pytestmark = pytest.mark.integration
QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


@pytest.fixture
def node(ros_domain_id):
    with own_node('dq_fk_test_raw_input') as node:
        yield node


def test_bytes_published_raw_arrive_in_order_with_their_sequence_numbers(node):
    pub = node.create_publisher(String, 'raw_io', QOS)
    send = raw_publisher(pub)
    assert send is not pub.publish  # this rclpy has the handle's publish_raw
    got = []
    thread = RawSubscriptionThread(node, String, '/raw_io', QOS,
                                   lambda raw, info: got.append((raw, info)))
    try:
        wait_for_match(pub, thread.subscription)
        for k in range(50):
            send(serialize_message(String(data=f'message {k}')))
        assert wait_until(lambda: len(got) == 50)
    finally:
        thread.close()
    assert [deserialize_message(raw, String).data for raw, _ in got] == \
        [f'message {k}' for k in range(50)]
    numbers = [info['publication_sequence_number'] for _, info in got]
    assert numbers == list(range(numbers[0], numbers[0] + 50))


def test_a_batch_window_delays_the_next_look_and_loses_nothing(node):
    """With ``batch_s`` the thread looks again only that long after handing messages over."""
    pub = node.create_publisher(String, 'raw_io', QOS)
    got = []
    thread = RawSubscriptionThread(node, String, '/raw_io', QOS,
                                   lambda raw, info: got.append((time.monotonic(), raw)),
                                   batch_s=0.4)
    try:
        wait_for_match(pub, thread.subscription)
        pub.publish(String(data='first'))
        assert wait_until(lambda: len(got) == 1)
        sent = [time.monotonic()]
        for k in range(5):  # while the thread sleeps: all handed over after its window
            pub.publish(String(data=f'then {k}'))
        assert wait_until(lambda: len(got) == 6)
    finally:
        thread.close()
    assert [deserialize_message(raw, String).data for _, raw in got] == \
        ['first'] + [f'then {k}' for k in range(5)]
    # the window starts when 'first' was handed over, before the others were sent: they
    # waited for the rest of it (0.4 s minus the time between the two)
    assert got[1][0] - got[0][0] >= 0.4 - 0.02
    assert got[1][0] > sent[0]


def os_thread_names():
    return [open(f'/proc/self/task/{task}/comm').read().strip()
            for task in os.listdir('/proc/self/task')]


@pytest.mark.skipif(not sys.platform.startswith('linux'), reason='thread names from /proc')
def test_the_input_thread_carries_a_name_top_shows(node):
    assert 'dq_fk input' not in os_thread_names()
    thread = RawSubscriptionThread(node, String, '/raw_io', QOS, lambda raw, info: None)
    try:
        assert wait_until(lambda: 'dq_fk input' in os_thread_names())
    finally:
        thread.close()
    assert wait_until(lambda: 'dq_fk input' not in os_thread_names())


def test_take_queued_hands_over_what_is_queued_up_to_a_limit(node):
    pub = node.create_publisher(String, 'raw_queue', QOS)
    sub = node.create_subscription(String, 'raw_queue', lambda _: None, QOS, raw=True)
    wait_for_match(pub, sub)
    for k in range(10):
        pub.publish(String(data=str(k)))
    first, rest = [], []

    def took_first():   # taken as they arrive: each call takes at most its limit
        assert take_queued(sub, first.append, limit=3 - len(first)) <= 3
        return len(first) == 3

    def took_rest():
        take_queued(sub, lambda raw, info: rest.append(info), with_info=True)
        return len(rest) == 7
    assert wait_until(took_first) and wait_until(took_rest)
    assert take_queued(sub, first.append) == 0
    assert [deserialize_message(raw, String).data for raw in first] == ['0', '1', '2']
    assert len(rest) == 7 and all('publication_sequence_number' in info for info in rest)


def test_raw_publisher_falls_back_to_publish_without_publish_raw():
    class Handle:
        pass

    class Publisher:
        handle = Handle()

        def publish(self, data):
            return data

    publisher = Publisher()
    assert raw_publisher(publisher)(b'x') == b'x'


def test_a_callback_that_raises_is_counted_and_the_thread_goes_on(node):
    """The input thread ended silently on its callback's first exception (no more /tf)."""
    pub = node.create_publisher(String, 'raw_io', QOS)
    got, reported = [], []

    def callback(raw, info):
        text = deserialize_message(raw, String).data
        if text.startswith('bad'):
            raise ValueError(text)
        got.append(text)
    thread = RawSubscriptionThread(node, String, '/raw_io', QOS, callback,
                                   on_error=reported.append)
    try:
        wait_for_match(pub, thread.subscription)
        for k in range(20):
            pub.publish(String(data=f'bad {k}' if k % 2 else f'good {k}'))
        assert wait_until(lambda: len(got) == 10)
    finally:
        thread.close()
    assert got == [f'good {k}' for k in range(0, 20, 2)]
    assert thread.errors == 10 and [str(e) for e in reported] == \
        [f'bad {k}' for k in range(1, 20, 2)]
