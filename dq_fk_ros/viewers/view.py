"""
dq_fk_view: the robot and every TF frame, live in a browser (no RViz needed).

An rclpy node takes /tf, /tf_static and /robot_description from any publisher; a local web
server (aiohttp) serves one page (three.js and urdf-loader, from npm) and streams every
frame's pose in the fixed frame to it over a WebSocket, at most ``--rate`` times a second
and only the latest poses, whatever the TF rate. The page draws the URDF placed by TF, each
frame's axes and name, a grid, and a panel with the selected frame's pose.

    dq_fk_view [--host 127.0.0.1] [--port 8765] [--fixed-frame F] [--select F] [--rate 30]
               [--joint-panel] [--urdf-dir DIR]

With ``--joint-panel`` (``dq_fk show`` starts it so) the page has a slider per moving joint
and the view publishes ``sensor_msgs/JointState`` on ``joint_states`` from them,
``PANEL_RATE_HZ`` times a second, as joint_state_publisher_gui
(:mod:`dq_fk_ros.viewers.view_panel`).

Messages to the page are JSON: ``{"type": "robot", "urdf": ...}`` when the description
changes, and ``{"type": "frames", "fixed_frame": ..., "select": ..., "stamp_ns": the
newest /tf stamp, "frames": [[name, parent, x, y, z, qx, qy, qz, qw, stale], ...]}``.
Messages from pages are read and, but for ``{"type": "hello"}``, ignored; anything else
(not JSON, binary, too big, nested too deeply) is counted in ``/status``.

This module is the program: its rclpy node (:func:`make_node`) and command line; what it
shows is :class:`~dq_fk_ros.viewers.view_state.ViewState`, the web server
:mod:`dq_fk_ros.viewers.view_web` (which says who may connect).
"""

import argparse
import asyncio
import os
import signal
import sys
import threading
from typing import Optional, TYPE_CHECKING

from dq_fk_ros.description.packages import PackageResolver
from dq_fk_ros.messages.outputs import ROBOT_DESCRIPTION, TF, TF_STATIC
from dq_fk_ros.ros.executables import (
    add_mesh_options, check_mesh_options, run_main, VIEWER_PORT)
from dq_fk_ros.viewers.view_state import STALE_AFTER_S, ViewState
from dq_fk_ros.viewers.view_web import DEFAULT_RATE_HZ, make_app, web_root

if TYPE_CHECKING:  # rclpy is imported where used: --help answers without it
    from rclpy.node import Node

DEFAULT_PORT = VIEWER_PORT
MAX_CONNECTIONS = 256        # open at once; one more is closed as it comes (fds stay free)
HEADER_TIMEOUT_S = 10.0      # a connection's first request must have its headers by then
KEEPALIVE_TIMEOUT_S = 15.0   # an idle connection between requests is closed after this
SHUTDOWN_TIMEOUT_S = 3.0     # on SIGINT: requests in progress get this long (aiohttp: 60)
TF_QUEUE_DEPTH = 1000  # /tf messages DDS keeps for the view between two takes
PANEL_RATE_HZ = 10.0   # joint states from the panel a second (joint_state_publisher's rate)


def make_node(state, context=None) -> 'Node':
    """Return the rclpy node that feeds ``state`` from /tf, /tf_static, /robot_description."""
    from dq_fk_ros.ros.raw_input import take_queued
    import rclpy
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String
    from tf2_msgs.msg import TFMessage

    def transforms_of(msg):
        return [(t.header.frame_id, t.child_frame_id,
                 (t.transform.translation.x, t.transform.translation.y,
                  t.transform.translation.z, t.transform.rotation.x, t.transform.rotation.y,
                  t.transform.rotation.z, t.transform.rotation.w)) for t in msg.transforms]

    node = Node('dq_fk_view', context=context)
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    # /tf: serialized, on a helper node no executor spins, taken only when poses are sent
    # (tens of times a second, whatever the TF rate: nothing wakes per message; a deep queue
    # holds what comes between), and only each publisher's newest message is read; best
    # effort matches every /tf publisher
    node.tf_input = rclpy.create_node('_dq_fk_view_tf', context=node.context,
                                      start_parameter_services=False, enable_rosout=False)
    subscription = node.tf_input.create_subscription(
        TFMessage, TF.topic, lambda _: None,
        QoSProfile(depth=TF_QUEUE_DEPTH, reliability=ReliabilityPolicy.BEST_EFFORT), raw=True)
    state.poll_tf = lambda: take_queued(subscription, state.take_raw_tf)
    node.create_subscription(TFMessage, TF_STATIC.topic,
                             lambda m: state.take_transforms(transforms_of(m), True),
                             QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                        durability=DurabilityPolicy.TRANSIENT_LOCAL))
    node.create_subscription(String, ROBOT_DESCRIPTION.topic,
                             lambda m: state.take_description(m.data), latched)
    if state.panel is not None:
        from sensor_msgs.msg import JointState
        publisher = node.create_publisher(JointState, 'joint_states', 10)

        def publish_panel():
            names, positions = state.panel.joint_state()
            if names:
                msg = JointState(name=names, position=positions)
                msg.header.stamp = node.get_clock().now().to_msg()
                publisher.publish(msg)
        node.create_timer(1.0 / PANEL_RATE_HZ, publish_panel)
    return node


def parse_args(argv) -> argparse.Namespace:
    """Return the command line's options (ROS arguments already removed)."""
    parser = argparse.ArgumentParser(
        prog='dq_fk_view', description='The robot and every TF frame, live in a browser.')
    parser.add_argument('--host', default='127.0.0.1',
                        help='address to listen on (default 127.0.0.1: this machine only)')
    parser.add_argument('--port', type=int, default=DEFAULT_PORT,
                        help=f'port (default {DEFAULT_PORT}; 0: any free one)')
    parser.add_argument('--allow-host', action='append', default=[], metavar='HOST',
                        help='a host name or address pages may use besides loopback and '
                        '--host (repeat for more; needed when --host binds a wildcard)')
    parser.add_argument('--fixed-frame', default='',
                        help='frame the poses are shown in (default: the root of the tree)')
    parser.add_argument('--select', default='',
                        help='frame selected at start (default: the deepest frame)')
    parser.add_argument('--rate', type=float, default=DEFAULT_RATE_HZ,
                        help=f'poses sent to pages per second at most (default '
                        f'{DEFAULT_RATE_HZ:g})')
    parser.add_argument('--joint-panel', action='store_true',
                        help='a slider per moving joint; publish their JointState on '
                        'joint_states (as joint_state_publisher_gui)')
    parser.add_argument('--urdf-dir', metavar='DIR',
                        help="the folder of the robot file you chose: the URDF's relative mesh "
                        'paths resolve inside it (dq_fk show sets it)')
    add_mesh_options(parser)
    parser.add_argument('--stale-after', type=float, default=STALE_AFTER_S,
                        help='seconds without an update after which a frame is greyed')
    args = parser.parse_args(argv)
    if not (0 <= args.port <= 65535):
        parser.error(f'--port {args.port}: give 0..65535')
    if not (0 < args.rate <= 1000):
        parser.error(f'--rate {args.rate:g}: give more than 0 and at most 1000')
    if not (args.stale_after > 0):
        parser.error('--stale-after: give a positive number of seconds')
    check_mesh_options(parser, args)
    if args.urdf_dir is not None and not os.path.isdir(args.urdf_dir):
        parser.error(f'--urdf-dir {args.urdf_dir}: no such folder')
    return args


class Connections:
    """The server's open connections, oldest first, each 'headers', 'http' or 'websocket'."""

    def __init__(self, counts, cap=MAX_CONNECTIONS):
        """Count what is dropped in ``counts`` (the view's /status)."""
        self.counts, self.cap, self.open = counts, cap, {}

    def make_room(self) -> bool:
        """Say whether a new connection may come in, dropping an old one if need be."""
        if len(self.open) < self.cap:
            return True
        for kind in ('headers', 'http'):  # a half-sent request first, then the oldest request
            for proto, state in self.open.items():
                if state == kind:
                    proto.drop('evicted_connections')
                    return True
        self.counts['refused_connections'] = self.counts.get('refused_connections', 0) + 1
        return False


class GuardedProtocol(asyncio.Protocol):
    """
    aiohttp's request handler for one connection, within the server's limits.

    At most MAX_CONNECTIONS open at once (:class:`Connections`): at the cap, a new
    connection takes the place of the oldest one still sending its first request's headers
    (a half-sent request holds no place a real client needs), else of the oldest plain HTTP
    one (a page's WebSocket is kept); with only WebSockets open it is closed as it comes.
    The first request's headers (up to the blank line) within HEADER_TIMEOUT_S, else the
    connection is closed. Between requests, aiohttp's keep-alive timeout; WebSocket
    messages, its own size limit and heartbeat. Everything else is the inner protocol's.
    """

    def __init__(self, inner, loop, connections):
        """Wrap ``inner`` (aiohttp's RequestHandler) as one of ``connections``."""
        self.inner, self.loop, self.connections = inner, loop, connections
        self.timer, self.transport, self.head, self.counted = None, None, b'', False

    def connection_made(self, transport) -> None:
        """Take the connection if there is room, and start the header clock."""
        self.transport = transport
        if not self.connections.make_room():
            transport.abort()
            return
        self.counted = True
        self.connections.open[self] = 'headers'
        self.timer = self.loop.call_later(HEADER_TIMEOUT_S, self.drop, 'slow_requests')
        self.inner.connection_made(transport)

    def drop(self, why) -> None:
        """Close the connection now, counted under ``why``; its place is free at once."""
        counts = self.connections.counts
        counts[why] = counts.get(why, 0) + 1
        self.transport.abort()
        self.connection_lost(None)  # (abort's own call later finds it gone)

    def data_received(self, data) -> None:
        """Pass data on; the header clock stops at the first request's blank line."""
        if not self.counted:
            return
        if self.timer is not None:
            self.head = (self.head + data)[-8192:]
            if b'\r\n\r\n' in self.head:
                self.timer.cancel()
                upgrade = b'upgrade: websocket' in self.head.lower()
                self.connections.open[self] = 'websocket' if upgrade else 'http'
                self.timer, self.head = None, b''
        self.inner.data_received(data)

    def eof_received(self) -> Optional[bool]:
        """Pass the end of the stream on."""
        return self.inner.eof_received() if self.counted else None

    def pause_writing(self) -> None:
        """Pass flow control on."""
        if self.counted:
            self.inner.pause_writing()

    def resume_writing(self) -> None:
        """Pass flow control on."""
        if self.counted:
            self.inner.resume_writing()

    def connection_lost(self, exc) -> None:
        """Free the connection's place."""
        if self.timer is not None:
            self.timer.cancel()
            self.timer = None
        if self.counted:
            self.counted = False
            self.connections.open.pop(self, None)
            self.inner.connection_lost(exc)


async def serve(args, state, ready=None):
    """Run the web server until SIGINT/SIGTERM; print the address to open."""
    from aiohttp import web
    bound = [] if args.host in ('0.0.0.0', '::', '') else [args.host]
    app = make_app(state, args.rate, allowed_hosts=tuple(bound + args.allow_host))
    runner = web.AppRunner(app, handle_signals=False, keepalive_timeout=KEEPALIVE_TIMEOUT_S,
                           max_line_size=8190, max_field_size=8190,
                           shutdown_timeout=SHUTDOWN_TIMEOUT_S)
    await runner.setup()
    loop = asyncio.get_running_loop()
    server = None
    try:
        connections = Connections(state.counts)
        server = await loop.create_server(
            lambda: GuardedProtocol(runner.server(), loop, connections), args.host,
            args.port, backlog=128, reuse_address=True)
        host, port = server.sockets[0].getsockname()[:2]
        shown = f'[{host}]' if ':' in host else host
        print(f'dq_fk_view: open http://{shown}:{port}/', flush=True)
        stop = asyncio.Event()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        await stop.wait()
    finally:
        if server is not None:
            server.close()
        await runner.cleanup()


def main(argv=None) -> int:
    """Run dq_fk_view (as ``ros2 run dq_fk_ros dq_fk_view``); return the exit code."""
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    from rclpy.utilities import remove_ros_args
    argv = sys.argv if argv is None else argv
    args = parse_args(remove_ros_args(argv)[1:])
    try:
        web_root()
        import aiohttp  # noqa: F401 (say plainly if it is missing)
    except (FileNotFoundError, ImportError) as exc:
        print(f'dq_fk_view: {exc} (make setup installs what it needs)', file=sys.stderr)
        return 1
    from dq_fk_ros.viewers.view_panel import JointPanel
    state = ViewState(args.fixed_frame, args.select, args.stale_after,
                      PackageResolver(args.packages), args.mesh_dir,
                      panel=JointPanel() if args.joint_panel else None, urdf_dir=args.urdf_dir)
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    node = make_node(state)
    executor = SingleThreadedExecutor()
    executor.add_node(node)

    def spin():
        try:
            executor.spin()
        except (ExternalShutdownException, Exception):  # shutting down
            pass
    thread = threading.Thread(target=spin, name='dq_fk_view ROS', daemon=True)
    thread.start()
    try:
        asyncio.run(serve(args, state))
    except OSError as exc:  # the port is taken, the address is not ours
        print(f'dq_fk_view: cannot listen on {args.host}:{args.port}: {exc.strerror or exc}',
              file=sys.stderr)
        return 1
    finally:
        executor.shutdown(timeout_sec=1.0)
        node.tf_input.destroy_node()
        node.destroy_node()
        rclpy.try_shutdown()
        thread.join(timeout=2.0)
    return 0


if __name__ == '__main__':
    sys.exit(run_main(main))
