"""tf2_ros's Buffer surface: async lookups, transform with registrations, clock jumps."""

import threading

from dq_fk_ros import tf
from dq_fk_ros.ros.tf_registration import (BufferInterface, convert, ConvertRegistration,
                                           NotImplementedException, Stamped,
                                           TransformRegistration, TypeException)
from geometry_msgs.msg import PointStamped, PoseStamped, TransformStamped, Vector3Stamped
import pytest
from rclpy.duration import Duration
from rclpy.time import Time


def transform(parent, child, seconds, x=1.0):
    msg = TransformStamped()
    msg.header.frame_id, msg.child_frame_id = parent, child
    msg.header.stamp = Time(seconds=seconds).to_msg()
    msg.transform.translation.x = x
    msg.transform.rotation.w = 1.0
    return msg


def test_the_setters_return_none_as_tf2_ros():
    buffer = tf.Buffer()
    assert buffer.set_transform(transform('a', 'b', 1), 'u') is None
    assert buffer.set_transform_static(transform('a', 'c', 1), 'u') is None


def test_an_async_lookup_of_what_is_there_finishes_at_once():
    buffer = tf.Buffer()
    t = transform('foo', 'bar', 3)
    buffer.set_transform(t, 'u')
    for coro in (buffer.lookup_transform_async('foo', 'bar', Time(seconds=3)),
                 buffer.lookup_transform_full_async('foo', Time(seconds=3), 'bar',
                                                    Time(seconds=3), 'foo')):
        with pytest.raises(StopIteration) as done:
            coro.send(None)
        assert done.value.value == t


def test_an_async_lookup_waits_for_the_data_and_the_future_holds_it():
    buffer = tf.Buffer()
    coro = buffer.lookup_transform_async('foo', 'bar', Time(seconds=3))
    coro.send(None)                       # waiting: nothing stored yet
    future = buffer.wait_for_transform_async('foo', 'bar', Time(seconds=3))
    assert not future.done()
    buffer.set_transform(transform('foo', 'other', 3), 'u')   # not what is waited for
    assert not future.done()
    t = transform('foo', 'bar', 3)
    buffer.set_transform(t, 'u')
    assert future.done() and future.result() == t
    with pytest.raises(StopIteration) as done:
        coro.send(None)
    assert done.value.value == t
    assert buffer._new_data_callbacks == []   # each waiter forgotten once done


def test_a_listener_store_wakes_an_async_wait_too():
    buffer = tf.Buffer()
    future = buffer.wait_for_transform_full_async('a', Time(), 'b', Time(), 'a')
    buffer.set_raw([('a', 'b', 5, (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))], 'peer')
    assert future.done() and future.result().child_frame_id == 'b'


def test_a_wait_from_another_thread_ends_when_the_data_come():
    buffer = tf.Buffer()
    got = []
    waiter = threading.Thread(target=lambda: got.append(buffer.lookup_transform(
        'a', 'b', Time(seconds=1), timeout=Duration(seconds=30))))
    waiter.start()
    buffer.set_transform(transform('a', 'b', 1), 'u')
    waiter.join(30)
    assert got and got[0].child_frame_id == 'b'


def test_a_clock_jumping_back_clears_the_buffer(caplog):
    buffer = tf.Buffer()
    buffer.set_transform(transform('a', 'b', 1), 'u')
    buffer.time_jump_callback(None)
    assert not buffer.can_transform('a', 'b', Time(seconds=1))
    assert 'Detected jump back in time. Clearing tf buffer.' in caplog.text


def test_transform_moves_a_message_into_the_target_frame_at_its_stamp():
    buffer = tf.Buffer()
    buffer.set_transform(transform('base', 'camera', 2, x=0.5), 'u')
    point = PointStamped()
    point.header.frame_id, point.header.stamp = 'camera', Time(seconds=2).to_msg()
    point.point.x = 1.0
    out = buffer.transform(point, 'base')
    assert (out.header.frame_id, out.point.x) == ('base', 1.5)
    out = buffer.transform(point, 'base', new_type=PointStamped)   # converted: a copy
    assert out.point.x == 1.5
    out = buffer.transform_full(point, 'base', Time(seconds=2), 'base',
                                timeout=Duration(seconds=1))
    assert out.point.x == 1.5


class Marker:
    """A message type of a user's: a header and a value."""

    def __init__(self):
        self.header = PointStamped().header
        self.value = 0.0


def test_a_users_registration_is_used_and_not_replaced():
    buffer = tf.Buffer()
    buffer.set_transform(transform('base', 'camera', 2, x=0.5), 'u')
    TransformRegistration().add(Marker, lambda m, t: ('moved', t.transform.translation.x))
    marker = Marker()
    marker.header.frame_id, marker.header.stamp = 'camera', Time(seconds=2).to_msg()
    assert buffer.transform(marker, 'base') == ('moved', 0.5)
    TransformRegistration().add_default(Marker, lambda m, t: 'not mine')
    assert buffer.transform(marker, 'base') == ('moved', 0.5)


def test_an_unknown_type_is_tf2s_type_exception():
    buffer = tf.Buffer()
    with pytest.raises(TypeException, match='is not loaded or supported') as raised:
        buffer.transform(object(), 'base')
    assert 'object' in raised.value.errstr


def test_convert_direct_by_copy_and_through_a_message():
    point = PointStamped()
    point.point.x = 2.0
    copied = convert(point, PointStamped)
    assert copied == point and copied is not point
    ConvertRegistration().add_convert((PointStamped, float), lambda p: p.point.x)
    assert convert(point, float) == 2.0
    with pytest.raises(TypeException):
        convert(Marker(), Vector3Stamped)   # no conversion of a Marker to a message
    assert Stamped(PoseStamped(), Time(seconds=1).to_msg(), 'f').header.frame_id == 'f'


def test_an_interface_without_lookups_says_so():
    interface = BufferInterface()
    for call in (lambda: interface.lookup_transform('a', 'b', Time()),
                 lambda: interface.can_transform('a', 'b', Time()),
                 lambda: interface.lookup_transform_full('a', Time(), 'b', Time(), 'a'),
                 lambda: interface.can_transform_full('a', Time(), 'b', Time(), 'a')):
        with pytest.raises(NotImplementedException):
            call()
