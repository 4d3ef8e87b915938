"""
dq_fk_foxglove: the robot live in Foxglove on a pip-only ROS, without foxglove_bridge.

    dq_fk_foxglove [--host 127.0.0.1] [--port 8765] [--package NAME=DIR] [--mesh-dir DIR]
                   [--rate 30] [--allow-origin ORIGIN] [--allow-host NAME]

An rclpy node on the same DDS domain takes ``/tf``, ``/tf_static`` (transient local),
``robot_description`` (transient local), ``joint_states`` and every pose topic
(``geometry_msgs/PoseStamped`` topics with ``/pose/`` in their name: each ``dq_fk_node``'s
``~/pose/<frame>``) from any publisher; the Foxglove SDK's WebSocket server (``foxglove-sdk``,
the optional extra ``dq_fk_ros[foxglove]``) serves them (:mod:`dq_fk_ros.viewers.foxglove_feed`
says how): at most ``--rate`` messages a second per channel, the newest only, whatever the
input rate. The Foxglove app fetches the URDF's meshes (``package://``) through the server's
asset handler, which reads exactly the mesh files the current URDF names
(:class:`~dq_fk_ros.description.meshes.MeshAssets`, the allow-list of ``dq_fk_view``). It
listens on 127.0.0.1 unless ``--host`` says otherwise: anyone who reaches the port sees the
robot and may fetch its meshes (docs/foxglove.md, "Security"). The SDK's server listens on a
random loopback address behind :class:`~dq_fk_ros.viewers.foxglove_gate.Gate`, which refuses
foreign web pages (``Host``, ``Origin``), bounds connections and handshakes, and holds asset
answers to a byte budget; the SDK's own log lines are rate-limited (:class:`LogRateLimit`).

The ROS subscriptions of ``joint_states`` and of a pose topic exist only while a Foxglove
client subscribes to their channel (``dq_fk_node`` publishes a pose topic only while
someone reads it), and keep the newest message only (a queue of one); ``/tf`` is always
taken, every message, for each publisher's newest (an odometry's and a robot's).
"""

import argparse
import logging
import sys
import threading
import time

from dq_fk_ros.messages.outputs import ROBOT_DESCRIPTION, TF, TF_STATIC
from dq_fk_ros.ros.executables import (
    add_mesh_options, check_mesh_options, run_main, VIEWER_PORT)

DEFAULT_PORT = VIEWER_PORT
DEFAULT_RATE_HZ = 30.0
DISCOVERY_PERIOD_S = 2.0   # how often new pose topics are looked for
QUEUE_DEPTH = 1000         # serialized /tf messages DDS keeps between two flushes
MESSAGE_BACKLOG = 256      # messages queued per client before the oldest are dropped
MISSING = ('dq_fk_foxglove needs the Foxglove SDK: pip install "dq_fk_ros[foxglove]" '
           '(or pip install foxglove-sdk; make setup installs it)')


def parse_args(argv) -> argparse.Namespace:
    """Return the command line's options (ROS arguments already removed)."""
    parser = argparse.ArgumentParser(
        prog='dq_fk_foxglove',
        description='The robot live in Foxglove (Open connection > Foxglove WebSocket > '
        'ws://127.0.0.1:8765): /tf, /tf_static, robot_description, joint_states and the pose '
        'topics of any publisher, through the Foxglove SDK.')
    parser.add_argument('--host', default='127.0.0.1',
                        help='address to listen on (default 127.0.0.1: this machine only; '
                        'another exposes the robot and its meshes to whoever reaches it)')
    parser.add_argument('--port', type=int, default=DEFAULT_PORT,
                        help=f'port (default {DEFAULT_PORT}; 0: any free one)')
    parser.add_argument('--rate', type=float, default=DEFAULT_RATE_HZ,
                        help=f'messages per second per channel at most, the newest '
                        f'(default {DEFAULT_RATE_HZ:g})')
    parser.add_argument('--allow-origin', action='append', default=[], metavar='ORIGIN',
                        help='a web page origin allowed besides the Foxglove app, loopback '
                        "pages and local files, as browsers send it ('https://x.example'; "
                        'repeatable)')
    parser.add_argument('--allow-host', action='append', default=[], metavar='NAME',
                        help='a host name clients may use besides loopback names, addresses '
                        "and --host (this machine's DNS name; repeatable)")
    add_mesh_options(parser)
    args = parser.parse_args(argv)
    if not (0 <= args.port <= 65535):
        parser.error(f'--port {args.port}: give 0..65535')
    if not (0 < args.rate <= 1000):
        parser.error(f'--rate {args.rate:g}: give more than 0 and at most 1000')
    check_mesh_options(parser, args)
    return args


class LogRateLimit(logging.Filter):
    """At most ``lines`` log records every ``period_s``; the number dropped said after."""

    def __init__(self, lines=5, period_s=10.0):
        """Pass ``lines`` records a period, then drop and count until the next."""
        super().__init__()
        self.lines, self.period_s = lines, period_s
        self.window_start, self.passed, self.dropped = -1e9, 0, 0

    def filter(self, record) -> bool:  # noqa: A003 (logging.Filter.filter)
        """Return whether ``record`` is written (the SDK's threads call this under the GIL)."""
        now = time.monotonic()
        if now - self.window_start >= self.period_s:
            if self.dropped:
                record.msg = f'{record.msg} ({self.dropped} lines before were not written)'
            self.window_start, self.passed, self.dropped = now, 0, 0
        self.passed += 1
        if self.passed > self.lines:
            self.dropped += 1
            return False
        return True


class _StderrHandler(logging.Handler):
    """Write to the ``sys.stderr`` of the moment (one replaced or closed since: no error)."""

    def emit(self, record) -> None:
        try:
            sys.stderr.write(self.format(record) + '\n')
            sys.stderr.flush()
        except Exception:  # noqa: B902 (a log line must never raise into the SDK's thread)
            pass


def route_sdk_log(foxglove) -> LogRateLimit:
    """Send the SDK's log lines to stderr through a :class:`LogRateLimit`; return it."""
    handler = _StderrHandler()
    handler.setFormatter(logging.Formatter('dq_fk_foxglove: sdk: %(message)s'))
    limit = LogRateLimit()
    handler.addFilter(limit)
    logger = logging.getLogger('foxglove')
    logger.addHandler(handler)
    logger.propagate = False
    foxglove.set_log_level('WARNING')
    return limit


class RosInput:
    """The rclpy side: subscriptions that feed a :class:`FoxgloveFeed`, and its timers."""

    def __init__(self, feed, rate_hz, context=None):
        """Subscribe on a node of its own; flush ``feed`` ``rate_hz`` times a second."""
        import rclpy
        from rclpy.node import Node
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import JointState
        from std_msgs.msg import String
        from tf2_msgs.msg import TFMessage
        self.feed = feed
        self.node = node = Node('dq_fk_foxglove', context=context)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.queued = QoSProfile(depth=QUEUE_DEPTH, reliability=ReliabilityPolicy.BEST_EFFORT)
        self.newest = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
        # kHz inputs, serialized, on a helper node no executor spins: taken at each flush,
        # only the newest of each read (nothing wakes per message)
        self.raw = rclpy.create_node('_dq_fk_foxglove_input', context=node.context,
                                     start_parameter_services=False, enable_rosout=False)
        self.tf = self.raw.create_subscription(TFMessage, TF.topic, lambda _: None, self.queued,
                                               raw=True)
        self.joint_state_type = JointState
        self.joint_states = None   # while a client wants /joint_states
        node.create_subscription(TFMessage, TF_STATIC.topic, self._on_static,
                                 QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                            durability=DurabilityPolicy.TRANSIENT_LOCAL))
        node.create_subscription(String, ROBOT_DESCRIPTION.topic,
                                 lambda m: feed.take_description(m.data), latched)
        self.poses = {}            # topic -> raw subscription, while a client wants it
        self.wanted = {}           # topic -> clients subscribed to its channel
        self.lock = threading.Lock()
        node.create_timer(DISCOVERY_PERIOD_S, self.discover)
        self.discover()
        # the flushes in a thread of their own, not an executor timer (an executor wake-up
        # costs more than a flush)
        self.period_s = 1.0 / rate_hz
        self.stopped = threading.Event()
        self.thread = threading.Thread(target=self._flush_loop, name='dq_fk_foxglove flush',
                                       daemon=True)
        self.thread.start()

    def _flush_loop(self):
        import time
        from dq_fk_ros.ros.raw_input import name_os_thread
        name_os_thread(b'dq_fk fox flush')  # in top -H and /proc: apart from the executor
        next_at = time.monotonic()
        while not self.stopped.is_set():
            try:
                self.flush()
            except Exception as exc:  # nothing a publisher sends may stop the flushes
                self.feed.counts['flush_errors'] = self.feed.counts.get('flush_errors', 0) + 1
                if self.feed.counts['flush_errors'] == 1:
                    self.feed.log(f'a flush failed (reported once): {exc!r}'[:300])
            next_at = max(next_at + self.period_s, time.monotonic())
            self.stopped.wait(next_at - time.monotonic())

    def _on_static(self, msg):
        self.feed.take_static([
            (t.header.frame_id, t.child_frame_id,
             (t.transform.translation.x, t.transform.translation.y, t.transform.translation.z,
              t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
              t.transform.rotation.w),
             t.header.stamp.sec * 1_000_000_000 + t.header.stamp.nanosec)
            for t in msg.transforms])

    def discover(self) -> None:
        """Advertise a channel for every pose topic on the graph (dq_fk_node's ~/pose/...)."""
        for topic, types in self.node.get_topic_names_and_types():
            if '/pose/' in topic and 'geometry_msgs/msg/PoseStamped' in types:
                self.feed.add_pose_topic(topic)

    def want(self, topic, delta) -> None:
        """Count a client (un)subscribing to ``topic``'s channel (from the server's thread)."""
        with self.lock:
            self.wanted[topic] = max(0, self.wanted.get(topic, 0) + delta)

    def _follow_wanted(self):
        """Subscribe to the topics clients want, and only those (in the executor)."""
        from geometry_msgs.msg import PoseStamped
        with self.lock:
            wanted = {t for t, n in self.wanted.items() if n > 0}
        poses = wanted & set(self.feed.pose_channels)
        for topic in poses - set(self.poses):
            self.poses[topic] = self.raw.create_subscription(
                PoseStamped, topic, lambda _: None, self.newest, raw=True)
        for topic in set(self.poses) - poses:
            self.raw.destroy_subscription(self.poses.pop(topic))
        if ('/joint_states' in wanted) != (self.joint_states is not None):
            if self.joint_states is None:
                self.joint_states = self.raw.create_subscription(
                    self.joint_state_type, 'joint_states', lambda _: None, self.newest,
                    raw=True)
            else:
                self.raw.destroy_subscription(self.joint_states)
                self.joint_states = None

    def flush(self) -> None:
        """Take what is queued (the newest of each kept) and send it to Foxglove."""
        from dq_fk_ros.ros.raw_input import take_queued
        try:
            self._follow_wanted()
            take_queued(self.tf, self.feed.take_raw_tf)
            if self.joint_states is not None:
                take_queued(self.joint_states, self.feed.take_joint_state)
            for topic, subscription in self.poses.items():
                take_queued(subscription, lambda raw, t=topic: self.feed.take_pose(t, raw))
        except Exception:  # a subscription destroyed meanwhile (shutting down)
            return
        self.feed.flush()

    def destroy(self) -> None:
        """Stop the flushes, then destroy both nodes."""
        self.stopped.set()
        self.thread.join(timeout=2.0)
        self.raw.destroy_node()
        self.node.destroy_node()


def make_listener(foxglove, ros, feed) -> object:
    """Return the server's listener: subscriptions to pose channels follow the clients."""
    class Listener(foxglove.ServerListener):
        def on_subscribe(self, client, channel):
            feed.subscribed(channel.topic)
            ros.want(channel.topic, +1)

        def on_unsubscribe(self, client, channel):
            ros.want(channel.topic, -1)
    return Listener()


def main(argv=None) -> int:
    """Run dq_fk_foxglove until SIGINT/SIGTERM; return the exit code."""
    from rclpy.utilities import remove_ros_args
    argv = sys.argv if argv is None else argv
    args = parse_args(remove_ros_args(argv)[1:])
    try:
        import foxglove
        import foxglove.channels  # noqa: F401
    except ImportError:
        print(MISSING, file=sys.stderr)
        return 1
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from dq_fk_ros.description.meshes import MeshAssets
    from dq_fk_ros.description.packages import PackageResolver
    from dq_fk_ros.viewers.foxglove_feed import FoxgloveFeed
    from dq_fk_ros.viewers.foxglove_gate import Gate, private_loopback_address

    def log(line):
        print(f'dq_fk_foxglove: {line}', file=sys.stderr, flush=True)
    rclpy.init(args=argv)
    ros = server = gate = None
    try:
        assets = MeshAssets(PackageResolver(args.packages), args.mesh_dir)
        feed = FoxgloveFeed(foxglove, assets, log)
        ros = RosInput(feed, args.rate)

        def fetch(uri):
            return assets.fetch(uri)
        route_sdk_log(foxglove)
        private = private_loopback_address()
        try:
            server = foxglove.start_server(
                name='dq_fk_foxglove', host=private, port=0, asset_handler=fetch,
                server_listener=make_listener(foxglove, ros, feed),
                message_backlog_size=MESSAGE_BACKLOG)
            gate = Gate(args.host, args.port, (private, server.port), assets.size, log,
                        allowed_hosts=args.allow_host, allowed_origins=args.allow_origin,
                        on_failure=lambda _: rclpy.try_shutdown(context=ros.node.context))
            port = gate.start()
        except Exception as exc:  # the port is taken, the address is not ours
            if isinstance(exc.__cause__, KeyboardInterrupt):
                return 0  # Ctrl-C while it started (pyo3: a SystemError caused by it): a stop
            print(f'dq_fk_foxglove: cannot listen on {args.host}:{args.port}: {exc}',
                  file=sys.stderr)
            return 1
        shown = f'[{args.host}]' if ':' in args.host else args.host
        print(f'dq_fk_foxglove: in Foxglove, Open connection > Foxglove WebSocket > '
              f'ws://{shown}:{port}', flush=True)
        executor = SingleThreadedExecutor(context=ros.node.context)
        executor.add_node(ros.node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if gate is not None:
            gate.stop()
        if server is not None:
            server.stop()
        if ros is not None:
            ros.destroy()
        rclpy.try_shutdown()
    return 1 if gate is not None and gate.failed else 0


if __name__ == '__main__':
    sys.exit(run_main(main))
