"""
dq_fk_ros.tf live over DDS: tf2_ros's Buffer and TransformListener beside dq_fk_node.

dq_fk_node and fake_joint_publisher run as processes on this run's domain; the listener runs
in a context of the test's own with its dedicated spin thread, as tf2_ros users write it.
"""

import math
import signal
import sys
import time

from dq_fk_ros import tf
from dq_fk_ros.testing import wait_for_match, wait_until
from geometry_msgs.msg import TransformStamped
from process_lines import process_lines
import pytest
from rclpy.duration import Duration
from rclpy.time import Time
from ros_harness import own_node, unique_node_name
from tf2_msgs.msg import TFMessage

pytestmark = pytest.mark.integration


def test_the_end_effector_at_fig_4_and_a_late_listener_gets_tf_static(dq_fk_robot):
    dq_fk_robot('rl15')   # the plugin's: the node and a joint source (zeros, 50 Hz)
    with own_node(unique_node_name('tf_listener_test')) as node:
        buffer = tf.Buffer()
        listener = tf.TransformListener(buffer, node, spin_thread=True)
        try:
            ee = buffer.lookup_transform('world', 'eeCarry_seg6', Time(),
                                         timeout=Duration(seconds=20))
            # [Zivkovic2023] Fig. 4: (1.025, 0, 1.445), quaternion x y z w (0.707107, 0,
            # 0.707107, 0)
            t, r = ee.transform.translation, ee.transform.rotation
            assert (t.x, t.y, t.z) == pytest.approx((1.025, 0.0, 1.445), abs=1e-9)
            sign = 1.0 if r.x >= 0 else -1.0
            assert [sign * v for v in (r.x, r.y, r.z, r.w)] == pytest.approx(
                [math.sqrt(0.5), 0.0, math.sqrt(0.5), 0.0], abs=1e-9)
            assert ee.header.frame_id == 'world' and ee.child_frame_id == 'eeCarry_seg6'
            assert ee.header.stamp.sec > 0   # the latest common time, from the joint states
            assert 'eeCarry_seg6: ' in buffer.all_frames_as_yaml()
        finally:
            listener.unregister()
        # a listener that joins late: /tf_static is latched (transient local)
        late = tf.Buffer()
        static_only = tf.TransformListener(late, node, spin_thread=True, static_only=True)
        try:
            assert wait_until(lambda: late.can_transform('world', 'base_seg0', Time()), 20)
            base = late.lookup_transform('world', 'base_seg0', Time())
            assert base.transform.translation.z == pytest.approx(0.73, abs=1e-12)
        finally:
            static_only.unregister()


def test_broadcasters_reach_a_listener_and_bytes_that_do_not_read_are_counted(
        ros_domain_id):
    with own_node(unique_node_name('tf_broadcast_test')) as node:
        buffer = tf.Buffer()
        listener = tf.TransformListener(buffer, node, spin_thread=True)
        try:
            static = tf.StaticTransformBroadcaster(node)
            moving = tf.TransformBroadcaster(node)
            wait_for_match(moving.pub_tf, listener.tf_thread.subscription)
            a = TransformStamped()
            a.header.frame_id, a.child_frame_id = 'test_map', 'test_odom'
            a.transform.translation.x, a.transform.rotation.w = 2.0, 1.0
            static.send_transform(a)
            for k in (1, 2):
                b = TransformStamped()
                b.header.frame_id, b.child_frame_id = 'test_odom', 'test_robot'
                b.header.stamp.sec = 100 + k
                b.transform.translation.y, b.transform.rotation.w = float(k), 1.0
                moving.send_transform([b])
            got = buffer.lookup_transform('test_map', 'test_robot', Time(seconds=101.5),
                                          timeout=Duration(seconds=10))
            assert (got.transform.translation.x, got.transform.translation.y) == \
                pytest.approx((2.0, 1.5), abs=1e-12)
            raw = node.create_publisher(TFMessage, '/tf', 10)
            raw.publish(b'\x00\x01\x00\x00\xff\xff\xff\xff')   # a count no message can hold
            assert wait_until(lambda: listener.counts['unreadable'] == 1, 10)
            with pytest.raises(tf.ExtrapolationException):
                buffer.lookup_transform('test_map', 'test_robot', Time(seconds=200))
            with pytest.raises(tf.LookupException):
                buffer.lookup_transform('test_map', 'nowhere', Time())
            assert not buffer.can_transform('test_map', 'nowhere', Time(),
                                            timeout=Duration(seconds=0.2))
        finally:
            listener.unregister()


def test_dq_fk_tf_echo_frames_and_monitor_beside_the_node(processes, dq_fk_robot, tmp_path):
    from dq_fk_ros.ros.executables import executable
    dq_fk_robot('rl15')
    echo = processes.start(executable('dq_fk') + ['tf', 'echo', 'world', 'eeCarry_seg6',
                                                  '--count', '3', '--rate', '5'])
    out, _ = echo.communicate(timeout=60)
    blocks = [b for b in out.split('At time ') if b.strip()]
    # the first may come before the first transform (a Failure block); the last have it
    assert '- Translation: [1.025, 0.000, 1.445]' in blocks[-1].replace('-0.000', '0.000'), out
    assert '- Rotation: in Quaternion (xyzw) [0.707, 0.000, 0.707, 0.000]' in blocks[-1], out
    # view_frames' way: it listens for a window (a loaded machine's discovery takes seconds)
    frames = processes.start(executable('dq_fk') + ['tf', 'frames', '--seconds', '8', '-o',
                                                    str(tmp_path / 'frames.pdf')])
    out, _ = frames.communicate(timeout=60)
    assert frames.returncode == 0, out
    text = open(tmp_path / 'frames.gv').read()
    assert '"wrist_seg5" -> "eeCarry_seg6"' in text and '"world" -> "base_seg0"' in text
    assert open(tmp_path / 'frames.pdf', 'rb').read(5) == b'%PDF-'
    # the monitor reports every second until Ctrl-C: stopped once a report has the chain
    monitor = processes.start(executable('dq_fk') + ['tf', 'monitor', 'world', 'eeCarry_seg6'])
    reader = process_lines(monitor)
    assert reader.until(lambda line: 'Frame: eeCarry_seg6, parent wrist_seg5' in line, 60), \
        ''.join(reader.lines)[-2000:]
    monitor.send_signal(signal.SIGINT)
    assert monitor.wait(timeout=30) == 0
    out = ''.join(reader.lines)
    assert 'Chain is: eeCarry_seg6 -> wrist_seg5 -> forearm_seg4' in out, out


def test_a_lookups_message_is_the_one_the_setters_make():
    """to_message puts each value in its field: the message made by hand is the same."""
    from dq_fk_ros.ros.tf_buffer import to_message
    pose = (1.5, -2.0, 3.25, 0.0, 0.6, 0.0, 0.8)
    made = to_message('world', 'tool', pose, 1_700_000_000_123_456_789)
    expected = TransformStamped()
    expected.header.frame_id, expected.child_frame_id = 'world', 'tool'
    expected.header.stamp.sec, expected.header.stamp.nanosec = 1_700_000_000, 123_456_789
    t, r = expected.transform.translation, expected.transform.rotation
    t.x, t.y, t.z, r.x, r.y, r.z, r.w = pose
    assert made == expected
    from rclpy.serialization import serialize_message
    assert serialize_message(made) == serialize_message(expected)


SHUTDOWN_ORDERS = {
    # the ROS 2 tutorials' order: spin, rclpy.shutdown(), the script ends
    'shutdown then exit': 'rclpy.shutdown()',
    'destroy_node then shutdown': 'node.destroy_node(); rclpy.shutdown()',
    'nothing at all': 'pass',
    "an exception in the user's code": "raise RuntimeError('a bug of the user')",
}


@pytest.mark.parametrize('spin_thread', [False, True])
@pytest.mark.parametrize('order', sorted(SHUTDOWN_ORDERS))
def test_a_listener_ends_cleanly_in_any_shutdown_order(processes, order, spin_thread):
    # exit 134, 'terminate called without an active exception', before: the listener's
    # input thread was still inside rcl's wait when the interpreter finalised
    script = (
        'import rclpy\n'
        'from dq_fk_ros import tf\n'
        'rclpy.init()\n'
        "node = rclpy.create_node('exit_order_listener')\n"
        'buffer = tf.Buffer()\n'
        f'listener = tf.TransformListener(buffer, node, spin_thread={spin_thread})\n'
        'for _ in range(3):\n'
        '    rclpy.spin_once(node, timeout_sec=0.02)\n' if not spin_thread else
        'import rclpy, time\n'
        'from dq_fk_ros import tf\n'
        'rclpy.init()\n'
        "node = rclpy.create_node('exit_order_listener')\n"
        'buffer = tf.Buffer()\n'
        f'listener = tf.TransformListener(buffer, node, spin_thread={spin_thread})\n'
        'time.sleep(0.1)\n') + SHUTDOWN_ORDERS[order] + '\n'
    proc = processes.start([sys.executable, '-c', script])
    out, _ = proc.communicate(timeout=30)
    expected = 1 if order.startswith('an exception') else 0
    assert proc.returncode == expected and 'terminate called' not in out, out[-2000:]


def test_a_listener_ends_cleanly_on_ctrl_c(processes):
    script = ('import rclpy\n'
              'from rclpy.executors import ExternalShutdownException\n'
              'from dq_fk_ros import tf\n'
              'rclpy.init()\n'
              "node = rclpy.create_node('ctrl_c_listener')\n"
              'listener = tf.TransformListener(tf.Buffer(), node)\n'
              'try:\n'   # a SIGINT at any moment from here on ends it cleanly
              "    print('spinning', flush=True)\n"
              '    rclpy.spin(node)\n'
              'except (KeyboardInterrupt, ExternalShutdownException):\n'
              '    pass\n'
              # rclpy's own race, not the listener's: its SIGINT handler shuts the context
              # down from another thread between try_shutdown's ok() and its shutdown() (a
              # fresh-clone run: "rcl_shutdown already called"); what is ours is asserted
              # below: no abort, exit 0
              'from rclpy._rclpy_pybind11 import RCLError\n'
              'try:\n'
              '    rclpy.try_shutdown()\n'
              'except RCLError as exc:\n'
              "    assert 'rcl_shutdown already called' in str(exc), exc\n")
    proc = processes.start([sys.executable, '-c', script])
    assert proc.stdout.readline().strip() == 'spinning'
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 0 and 'terminate called' not in out, out[-2000:]


def test_a_peer_repeating_one_stamp_loses_no_message_and_every_refusal_is_counted(
        ros_domain_id):
    # 200 transforms of one frame at one stamp a message: each insert had scanned every
    # sample of that stamp under the buffer lock, and the listener took 55 of 580 messages
    messages, per_message = 150, 200
    with own_node(unique_node_name('tf_repeat_test')) as node:
        buffer = tf.Buffer()
        listener = tf.TransformListener(buffer, node, spin_thread=True)
        try:
            moving = tf.TransformBroadcaster(node)
            wait_for_match(moving.pub_tf, listener.tf_thread.subscription)
            other = TransformStamped()
            other.header.frame_id, other.child_frame_id = 'rep_world', 'rep_other'
            other.header.stamp.sec, other.transform.rotation.w = 5, 1.0
            moving.send_transform(other)
            assert buffer.can_transform('rep_world', 'rep_other', Time(),
                                        timeout=Duration(seconds=10))
            batch = []
            for k in range(per_message):
                t = TransformStamped()
                t.header.frame_id, t.child_frame_id = 'rep_world', 'rep_peer'
                t.header.stamp.sec = 7
                t.transform.translation.x, t.transform.rotation.w = float(k), 1.0
                batch.append(t)
            answered = 0
            for _ in range(messages):
                moving.send_transform(batch)
                buffer.lookup_transform('rep_world', 'rep_other', Time())
                answered += 1
                time.sleep(0.01)
            assert wait_until(lambda: listener.counts['messages'] == messages + 1, 20), \
                listener.counts
            # the first sample of the stamp is held; every later one refused and counted
            # (the same values as the held one: a duplicate, taken once, tf2's rule)
            duplicates = messages - 1
            assert listener.counts['refused'] == messages * per_message - 1 - duplicates
            assert buffer.core.refused == {'TF_REPEATED_DATA': listener.counts['refused']}
            assert buffer.lookup_transform('rep_world', 'rep_peer', Time(seconds=7)) \
                .transform.translation.x == 0.0
            assert answered == messages
        finally:
            listener.unregister()
