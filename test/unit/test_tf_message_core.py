"""tf2_py's BufferCore (dq_fk_ros.ros.tf_message_core): messages and rclpy times in and out."""

import math

from builtin_interfaces.msg import Time as TimeMsg
from dq_fk_ros.ros.tf_message_core import duration_ns, MessageBufferCore, time_ns
from dq_fk_ros.transforms.exceptions import LookupException
from geometry_msgs.msg import TransformStamped
import pytest
from rclpy.duration import Duration
from rclpy.time import Time


def transform(parent, child, seconds, xyz=(0.0, 0.0, 0.0), yaw=0.0):
    msg = TransformStamped()
    msg.header.frame_id, msg.child_frame_id = parent, child
    msg.header.stamp = Time(nanoseconds=int(round(seconds * 1e9))).to_msg()
    msg.transform.translation.x, msg.transform.translation.y, msg.transform.translation.z = xyz
    msg.transform.rotation.z, msg.transform.rotation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    return msg


def test_times_are_taken_in_every_form_tf2_py_takes():
    assert time_ns(Time(seconds=1.5)) == 1_500_000_000
    assert time_ns(TimeMsg(sec=2, nanosec=7)) == 2_000_000_007
    assert time_ns(12) == 12
    assert duration_ns(Duration(seconds=0.25)) == 250_000_000
    with pytest.raises(TypeError, match='not float'):
        time_ns(1.5)
    with pytest.raises(TypeError, match='not str'):
        duration_ns('1')


def test_set_returns_none_and_the_lookup_is_the_message_set():
    core = MessageBufferCore()
    t = transform('bar', 'foo', 0.0, (2.0, 0.0, 0.0))
    assert core.set_transform(t, 'unittest') is None
    assert core.lookup_transform_core('bar', 'foo', Time()) == t
    assert core.can_transform_core('bar', 'foo', Time()) == (True, '')
    ok, why = core.can_transform_core('bar', 'baz', Time())
    assert not ok and 'baz' in why
    with pytest.raises(LookupException):
        core.lookup_transform_core(target_frame='bar', source_frame='baz', time=Time())


def test_a_refused_transform_is_counted_not_raised():
    core = MessageBufferCore()
    bad = transform('bar', 'bar', 1.0)
    assert core.set_transform(bad, 'peer') is None
    assert sum(core.core.refused.values()) == 1


def test_static_holds_at_every_time_and_dynamic_only_at_its_stamps():
    core = MessageBufferCore()
    core.set_transform_static(transform('a', 'b', 0.0), 'u')
    core.set_transform(transform('a', 'c', 0.0), 'u')
    assert core.can_transform_core('a', 'b', Time(seconds=0.5))[0]
    ok, why = core.can_transform_core('a', 'c', Time(seconds=0.5))
    assert not ok and 'extrapolation' in why
    assert core.lookup_transform_core('a', 'b', Time(seconds=0.5)).header.stamp == \
        Time(seconds=0.5).to_msg()


def test_latest_common_time_full_lookups_clear_and_the_frames_known():
    core = MessageBufferCore()
    for seconds in (0.0, 1.0, 0.5):
        core.set_transform(transform('bar', 'foo', seconds, (seconds, 0.0, 0.0)), 'u')
    core.set_transform_static(transform('bar', 'baz', 0.0, (0.0, 1.0, 0.0)), 'u')
    assert core.get_latest_common_time('bar', 'foo') == Time(seconds=1)
    full = core.lookup_transform_full_core('baz', Time(seconds=1), 'foo', Time(seconds=0.5),
                                           'bar')
    assert (full.transform.translation.x, full.transform.translation.y) == (0.5, -1.0)
    assert core.can_transform_full_core('baz', Time(), 'foo', Time(), 'bar') == (True, '')
    assert sorted(core._getFrameStrings()) == ['bar', 'baz', 'foo']
    assert core._frameExists('baz') and not core._frameExists('qux')
    assert 'Frame foo exists with parent bar.' in core.all_frames_as_string()
    assert 'foo:' in core.all_frames_as_yaml() and '"foo"' in core._allFramesAsDot()
    core.clear()
    assert not core.can_transform_core('bar', 'foo', Time())[0]
    with pytest.raises(LookupException):
        core.get_latest_common_time('bar', 'nope')


def moving(core, velocity=(0.0, 0.0, 0.0), omega=0.0, seconds=range(6)):
    for s in seconds:
        core.set_transform(transform('world', 'body', float(s),
                                     tuple(v * s for v in velocity), omega * s), 'u')


def test_velocity_of_a_frame_moving_straight_is_its_speed():
    core = MessageBufferCore()
    moving(core, velocity=(3.0, -1.0, 0.5))
    linear, angular = core.lookupVelocityCore('body', 'world', Time(seconds=2.0),
                                              Duration(seconds=1.0))
    assert linear == pytest.approx((3.0, -1.0, 0.5))
    assert angular == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)


def test_velocity_of_a_turning_frame_and_of_a_point_on_it():
    core = MessageBufferCore()
    moving(core, omega=0.4)
    linear, angular = core.lookupVelocityCore('body', 'world', Time(seconds=2.0),
                                              Duration(seconds=1.0))
    assert angular == pytest.approx((0.0, 0.0, 0.4))
    assert linear == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
    # a point 2 m along the body's x: v = w x r, r the point at t = 2 s in the world
    linear, angular = core.lookupVelocityFullCore('body', 'world', 'world', (2.0, 0.0, 0.0),
                                                  'body', Time(seconds=2.0),
                                                  Duration(seconds=1.0))
    r = (2.0 * math.cos(0.8), 2.0 * math.sin(0.8), 0.0)
    assert linear == pytest.approx((-0.4 * r[1], 0.4 * r[0], 0.0))


def test_velocity_near_the_newest_sample_averages_back_from_it():
    """tf2's rule: the interval ends at the latest common time (5 s here)."""
    core = MessageBufferCore()
    moving(core, velocity=(1.0, 0.0, 0.0))
    linear, _ = core.lookupVelocityCore('body', 'world', Time(seconds=5.0),
                                        Duration(seconds=2.0))
    assert linear == pytest.approx((1.0, 0.0, 0.0))
