"""tf2_ros's services over DDS: BufferClient (LookupTransform action), the tf2_frames service."""

import threading

from dq_fk_ros import tf
from dq_fk_ros.testing import wait_until
from geometry_msgs.msg import PointStamped, TransformStamped
import pytest
from rclpy.action import ActionServer
from rclpy.duration import Duration
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.time import Time
from ros_harness import own_node, unique_node_name
from rosgraph_msgs.msg import Clock
from tf2_msgs.action import LookupTransform
from tf2_msgs.msg import TF2Error
from tf2_msgs.srv import FrameGraph

pytestmark = pytest.mark.integration

CODES = {tf.LookupException: TF2Error.LOOKUP_ERROR,
         tf.ConnectivityException: TF2Error.CONNECTIVITY_ERROR,
         tf.ExtrapolationException: TF2Error.EXTRAPOLATION_ERROR}


def transform(parent, child, seconds, x):
    t = TransformStamped()
    t.header.frame_id, t.child_frame_id = parent, child
    t.header.stamp = Time(seconds=seconds).to_msg()
    t.transform.translation.x, t.transform.rotation.w = x, 1.0
    return t


class Spinning:
    """A node's executor spun in a thread until the block ends."""

    def __init__(self, node):
        self.executor = SingleThreadedExecutor(context=node.context)
        self.executor.add_node(node)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._spin, daemon=True)

    def _spin(self):
        while not self.stop.is_set():
            self.executor.spin_once(timeout_sec=0.05)

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.thread.join(10)
        self.executor.shutdown()


def serve_lookups(node, buffer, name):
    """Answer LookupTransform goals from ``buffer`` (what tf2_ros's C++ buffer_server does)."""
    def execute(goal_handle):
        request, result = goal_handle.request, LookupTransform.Result()
        try:
            if request.advanced:
                result.transform = buffer.lookup_transform_full(
                    request.target_frame, request.target_time, request.source_frame,
                    request.source_time, request.fixed_frame)
            else:
                result.transform = buffer.lookup_transform(
                    request.target_frame, request.source_frame, request.source_time)
            goal_handle.succeed()
        except tf.TransformException as error:
            result.error.error = CODES.get(type(error), TF2Error.TRANSFORM_ERROR)
            result.error.error_string = str(error)
            goal_handle.abort()
        return result
    return ActionServer(node, LookupTransform, name, execute)


def test_a_buffer_client_asks_a_server_and_raises_its_errors_as_tf2s(ros_domain_id):
    with own_node(unique_node_name('tf_buffer_client_test')) as node:
        served = tf.Buffer()
        served.set_transform(transform('map', 'odom', 2, 1.5), 'u')
        served.set_transform(transform('odom', 'base', 2, 0.25), 'u')
        server = serve_lookups(node, served, 'tf_lookup_test')
        client = tf.BufferClient(node, 'tf_lookup_test', timeout_padding=Duration(seconds=20))
        try:
            with Spinning(node):
                assert client.action_client.wait_for_server(timeout_sec=20)
                got = client.lookup_transform('map', 'base', Time(seconds=2),
                                              Duration(seconds=5))
                assert (got.header.frame_id, got.transform.translation.x) == ('map', 1.75)
                full = client.lookup_transform_full('map', Time(seconds=2), 'base',
                                                    Time(seconds=2), 'odom')
                assert full.transform.translation.x == 1.75
                with pytest.raises(tf.LookupException, match='nowhere'):
                    client.lookup_transform('map', 'nowhere', Time())
                with pytest.raises(tf.ExtrapolationException, match='extrapolation at time 9'):
                    client.lookup_transform('map', 'base', Time(seconds=9))
                assert client.can_transform('map', 'base', Time(seconds=2))
                assert not client.can_transform_full('map', Time(), 'nowhere', Time(), 'odom')
                stamped = PointStamped(header=transform('base', 'x', 2, 0.0).header)
                assert client.transform(stamped, 'map').point.x == 1.75
        finally:
            client.destroy()
            server.destroy()


def test_a_buffer_client_without_a_server_says_so_at_once(ros_domain_id):
    with own_node(unique_node_name('tf_buffer_client_alone')) as node:
        client = tf.BufferClient(node, 'no_server_here')
        try:
            with pytest.raises(tf.TimeoutException, match='not ready'):
                client.lookup_transform('a', 'b', Time())
        finally:
            client.destroy()


def test_a_buffer_given_a_node_serves_tf2_frames(ros_domain_id):
    with own_node(unique_node_name('tf_frames_test')) as node:
        buffer = tf.Buffer(node=node)
        buffer.set_transform(transform('map', 'odom', 2, 1.5), 'the_peer')
        client = node.create_client(FrameGraph, 'tf2_frames')
        with Spinning(node):
            assert client.wait_for_service(timeout_sec=20)
            done = threading.Event()
            future = client.call_async(FrameGraph.Request())
            future.add_done_callback(lambda _: done.set())
            assert done.wait(20)
        yaml_text = future.result().frame_yaml
        assert 'odom:' in yaml_text and "parent: 'map'" in yaml_text
        assert 'the_peer' in yaml_text


def test_a_buffer_on_a_node_with_sim_time_is_cleared_when_clock_goes_back(ros_domain_id):
    """A bag played again: /clock jumps back, the buffer forgets (tf2_ros's buffer.py)."""
    with own_node(unique_node_name('tf_clock_jump_test')) as node:
        node.set_parameters([Parameter('use_sim_time', Parameter.Type.BOOL, True)])
        buffer = tf.Buffer(node=node)
        clock = node.create_publisher(Clock, '/clock', 10)

        def tick(seconds):
            msg = Clock()
            msg.clock.sec = seconds
            clock.publish(msg)
        with Spinning(node):
            assert wait_until(lambda: (tick(100), node.get_clock().now().nanoseconds ==
                                       100 * 10**9)[1], 20)
            buffer.set_transform(transform('map', 'odom', 100, 1.0), 'bag')
            assert buffer.can_transform('map', 'odom', Time(seconds=100))
            assert wait_until(lambda: (tick(50), not buffer.can_transform(
                'map', 'odom', Time(seconds=100)))[1], 20)
        assert node.get_clock().now().nanoseconds == 50 * 10**9
