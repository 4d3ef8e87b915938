"""
dq_fk_view: the robot and every TF frame, live in a browser (no RViz needed).

An rclpy node takes /tf, /tf_static and /robot_description from any publisher; a local web
server (aiohttp) serves one page (three.js and urdf-loader, from npm) and streams every
frame's pose in the fixed frame to it over a WebSocket, at most ``--rate`` times a second
and only the latest poses, whatever the TF rate. The page draws the URDF placed by TF, each
frame's axes and name, a grid, and a panel with the selected frame's pose.

    dq_fk_view [--host 127.0.0.1] [--port 8765] [--fixed-frame F] [--select F] [--rate 30]

Messages to the page are JSON: ``{"type": "robot", "urdf": ...}`` when the description
changes, and ``{"type": "frames", "fixed_frame": ..., "select": ..., "stamp_ns": the
newest /tf stamp, "frames": [[name, parent, x, y, z, qx, qy, qz, qw, stale], ...]}``.
Messages from pages are read and, but for ``{"type": "hello"}``, ignored; anything else
(not JSON, binary, too big, nested too deeply) is counted in ``/status``.

Only this machine's pages get anything: every request must name a loopback host (or the
address the server listens on, or one given with ``--allow-host``) in its ``Host`` header,
so a web page that points its own domain at 127.0.0.1 (DNS rebinding) is refused; and a
WebSocket whose ``Origin`` is not the server's own is refused (another site's page open in
the same browser). Both answer 403.
"""

import argparse
import asyncio
import ipaddress
import json
import os
import signal
import sys
import threading
import time

from dq_fk_ros.description.meshes import check_mesh_file, mesh_allow_list
from dq_fk_ros.description.packages import PackageResolver
from dq_fk_ros.description.shipped import share_folders
from dq_fk_ros.description.urdf import is_helper_frame
from dq_fk_ros.kinematics.tree import compose_tree, depths, roots
from dq_fk_ros.messages.cdr import CdrError, TfLatest

DEFAULT_PORT = 8765
DEFAULT_RATE_HZ = 30.0
STALE_AFTER_S = 1.0
MAX_CLIENT_MESSAGE_BYTES = 64 * 1024
LOOPBACK_NAMES = ('localhost', 'localhost.localdomain', 'ip6-localhost')
TF_QUEUE_DEPTH = 1000  # /tf messages DDS keeps for the view between two takes
VENDOR_PACKAGES = ('three', 'urdf-loader')


def web_root():
    """Return the folder of the page (``web/``: installed share directory, or source tree)."""
    candidates = share_folders('web')
    pages = [f for f in candidates if os.path.isfile(os.path.join(f, 'index.html'))]
    for folder in pages:  # one with three.js and urdf-loader installed (npm ci) first
        if os.path.isdir(os.path.join(folder, 'node_modules', 'three')):
            return folder
    if pages:
        return pages[0]
    raise FileNotFoundError(f'the page of dq_fk_view is not in {" or ".join(candidates)}')


class ViewState:
    """What the page shows, shared by the ROS callbacks and the web server (under a lock)."""

    def __init__(self, fixed_frame='', select='', stale_after_s=STALE_AFTER_S, resolver=None,
                 mesh_dirs=(), log=None):
        """
        Start empty; ``fixed_frame`` and ``select`` empty: chosen from the TF tree.

        :param resolver: finds the packages of ``package://`` meshes (a
            :class:`PackageResolver`; default: the ament index and ``ROS_PACKAGE_PATH``).
        :param mesh_dirs: folders ``file://`` meshes may be in.
        :param log: called with one line per mesh that cannot be served (default: stderr).
        """
        self.lock = threading.Lock()
        self.resolver = resolver or PackageResolver()
        self.mesh_dirs = tuple(mesh_dirs)
        self.log = log or (lambda line: print(f'dq_fk_view: {line}', file=sys.stderr,
                                              flush=True))
        self.meshes = ()          # the MeshFiles of the current URDF: all that /mesh serves
        self.edges = {}          # child -> (parent, pose, static, monotonic time received)
        self.last_stamp_ns = 0   # the newest /tf stamp received (the page reports latency)
        # /tf arrives serialized (up to kHz): only the newest message of each layout
        # (publisher) is read, when poses are sent (tens of Hz)
        self.tf_latest = TfLatest()
        self.poll_tf = None       # takes what /tf has queued into take_raw_tf
        self.urdf = None
        self.urdf_version = 0
        self.fixed_frame = fixed_frame
        self.select = select
        self.stale_after_s = stale_after_s
        self.counts = {'tf_messages': 0, 'bad_input': 0, 'frames_sent': 0, 'skipped_sends': 0,
                       'clients': 0, 'clients_total': 0, 'refused_hosts': 0,
                       'refused_origins': 0}

    def take_transforms(self, transforms, static, stamp_ns=0):
        """Record ``[(parent, child, (x, y, z, qx, qy, qz, qw)), ...]`` as received now."""
        now = time.monotonic()
        with self.lock:
            self.last_stamp_ns = max(self.last_stamp_ns, stamp_ns)
            self.counts['tf_messages'] += 1
            for parent, child, pose in transforms:
                if parent and child and parent != child:
                    self.edges[child] = (parent, pose, static, now)

    def take_raw_tf(self, raw):
        """Keep a serialized /tf message if it is its layout's newest (bad bytes: counted)."""
        with self.lock:
            try:
                self.tf_latest.take(raw)
            except CdrError:  # not a TFMessage after all: counted, never fatal
                self.counts['bad_tf'] = self.counts.get('bad_tf', 0) + 1

    def take_description(self, text):
        """Record a new robot description (URDF XML) and the meshes it allows to be served."""
        with self.lock:
            if text == self.urdf:
                return
        meshes = mesh_allow_list(text, self.resolver, self.mesh_dirs)
        for mesh in meshes:
            if mesh.problem:
                self.log(f'{mesh.problem} (a grey box stands for it)')
        with self.lock:
            self.urdf = text
            self.meshes = meshes
            self.urdf_version += 1

    def robot_message(self):
        """Return the JSON text of the robot: its URDF and where the page gets each mesh."""
        with self.lock:
            urdf, meshes = self.urdf, self.meshes
        return json.dumps({'type': 'robot', 'urdf': urdf,
                           'meshes': {m.uri: m.url or None for m in meshes}})

    def mesh_path(self, index, name):
        """Return the file served as ``/mesh/<index>/<name>``, or None (not on the list)."""
        from urllib.parse import quote
        with self.lock:
            meshes = self.meshes
        if not (0 <= index < len(meshes)) or meshes[index].path is None or \
                meshes[index].url != f'/mesh/{index}/{quote(name)}':
            return None
        path = meshes[index].path
        try:  # as it is now: the file may have been replaced since the list was made
            if os.path.realpath(path) != path:
                return None
            check_mesh_file(path)
        except ValueError:
            return None
        return path

    def frames_message(self):
        """Return the JSON text of every frame's pose in the fixed frame (None: no frames)."""
        if self.poll_tf is not None:
            try:
                self.poll_tf()
            except Exception:  # the subscription is gone (shutting down)
                pass
        with self.lock:
            newest = self.tf_latest.pop()
        for transforms, stamp_ns in newest:
            self.take_transforms(transforms, False, stamp_ns)
        with self.lock:
            edges = {child: (parent, pose) for child, (parent, pose, _, _) in self.edges.items()}
            ages = {child: (static, received) for child, (_, _, static, received)
                    in self.edges.items()}
            stamp_ns = self.last_stamp_ns
        if not edges:
            return None
        root = self.fixed_frame or _largest_root(edges)
        poses = compose_tree(edges, root)
        below = depths(edges, root)
        select = self.select or _deepest(below)
        now = time.monotonic()
        frames = []
        for name in sorted(poses):
            static, received = ages[name]
            stale = not static and now - received > self.stale_after_s
            frames.append([name, edges[name][0], *poses[name], stale])
        return json.dumps({'type': 'frames', 'fixed_frame': root, 'select': select,
                           'stamp_ns': stamp_ns, 'frames': frames})


def _largest_root(edges):
    """Return the root with most frames below it ('world' on a tie)."""
    candidates = roots(edges) or [next(iter(edges))]
    return max(candidates, key=lambda r: (len(depths(edges, r)), r == 'world', r))


def _deepest(below):
    """Return the frame farthest from the root, not a URDF helper (the end effector, often)."""
    names = [n for n in below if not is_helper_frame(n)] or list(below)  # never a helper
    return min(names, key=lambda n: (-below[n], n)) if names else ''


def make_node(state, context=None):
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
        TFMessage, '/tf', lambda _: None,
        QoSProfile(depth=TF_QUEUE_DEPTH, reliability=ReliabilityPolicy.BEST_EFFORT), raw=True)
    state.poll_tf = lambda: take_queued(subscription, state.take_raw_tf)
    node.create_subscription(TFMessage, '/tf_static',
                             lambda m: state.take_transforms(transforms_of(m), True),
                             QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                        durability=DurabilityPolicy.TRANSIENT_LOCAL))
    node.create_subscription(String, 'robot_description',
                             lambda m: state.take_description(m.data), latched)
    return node


def host_allowed(host, allowed=()):
    """
    Whether a ``Host`` or ``Origin`` host name may reach the view.

    Loopback names and addresses always; ``allowed``: more names or addresses (the address
    the server listens on, ``--allow-host``). ``host`` without its port.
    """
    host = host.strip('[]').lower().rstrip('.')
    if host in LOOPBACK_NAMES or host in (a.lower() for a in allowed):
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _split_host(value):
    """Return the host of a ``Host`` header value (``name``, ``name:port``, ``[v6]:port``)."""
    value = value.strip()
    if value.startswith('['):
        return value[1:value.find(']')] if ']' in value else ''
    return value.rsplit(':', 1)[0] if value.count(':') == 1 else value


def make_app(state, rate_hz=DEFAULT_RATE_HZ, root=None, allowed_hosts=()):
    """
    Return the aiohttp application: the page, its scripts, /ws and /status.

    :param allowed_hosts: host names or addresses besides loopback that requests may name
        (see the module doc); anything else gets 403.
    """
    from aiohttp import web, WebSocketError, WSMsgType
    from urllib.parse import urlsplit
    root = root or web_root()
    clients = {}  # websocket -> task of its send in progress (only the latest is sent)

    @web.middleware
    async def guard(request, handler):
        """Refuse foreign hosts and origins (403); a failing request is a 404, not a 500."""
        if not host_allowed(_split_host(request.headers.get('Host', '')), allowed_hosts):
            with state.lock:
                state.counts['refused_hosts'] += 1
            return web.Response(status=403, text='forbidden host\n')
        origin = request.headers.get('Origin')
        if origin is not None and request.path == '/ws':
            try:
                parts = urlsplit(origin)
                same = parts.scheme == 'http' and parts.netloc.lower() == \
                    request.headers.get('Host', '').lower()
            except ValueError:
                same = False
            if not same:
                with state.lock:
                    state.counts['refused_origins'] += 1
                return web.Response(status=403, text='forbidden origin\n')
        try:
            return await handler(request)
        except web.HTTPException:
            raise
        except (OSError, ValueError):  # a path too long for the file system, and the like
            return web.Response(status=404, text='not found\n')

    async def index(_):
        return web.FileResponse(os.path.join(root, 'index.html'))

    async def app_js(_):
        return web.FileResponse(os.path.join(root, 'app.js'),
                                headers={'Content-Type': 'text/javascript'})

    async def mesh(request):
        """Serve a mesh of the current URDF's allow-list (``ViewState.mesh_path``), else 404."""
        try:
            index = int(request.match_info['index'])
        except ValueError:
            index = -1
        path = state.mesh_path(index, request.match_info['name'])
        if path is None:
            with state.lock:
                state.counts['refused_meshes'] = state.counts.get('refused_meshes', 0) + 1
            return web.Response(status=404, text='not found\n')
        kind = {'.stl': 'model/stl', '.dae': 'model/vnd.collada+xml',
                '.obj': 'model/obj'}[os.path.splitext(path)[1].lower()]
        return web.FileResponse(path, headers={'Content-Type': kind})

    async def no_icon(_):
        return web.Response(status=204)  # the page has none; a browser asks anyway

    async def status(_):
        with state.lock:
            body = dict(state.counts, frames=len(state.edges), robot=state.urdf is not None)
        return web.json_response(body)

    async def socket(request):
        ws = web.WebSocketResponse(max_msg_size=MAX_CLIENT_MESSAGE_BYTES, heartbeat=10.0)
        await ws.prepare(request)
        clients[ws] = None
        with state.lock:
            state.counts['clients'] = len(clients)
            state.counts['clients_total'] += 1
            urdf = state.urdf
        try:
            if urdf is not None:
                await ws.send_str(state.robot_message())
            text = state.frames_message()
            if text is not None:
                await ws.send_str(text)
            async for msg in ws:
                if msg.type == WSMsgType.ERROR:
                    break
                if not _good_client_message(msg, WSMsgType):
                    with state.lock:
                        state.counts['bad_input'] += 1
        finally:
            clients.pop(ws, None)
            with state.lock:
                state.counts['clients'] = len(clients)
        if isinstance(ws.exception(), WebSocketError):  # too big, not a WebSocket frame
            with state.lock:
                state.counts['bad_input'] += 1
        return ws

    async def send(ws, text):
        try:
            await ws.send_str(text)
        except Exception:  # the page went away meanwhile: its handler cleans up
            pass

    async def broadcast(app):
        last_text, last_urdf = None, 0
        period = 1.0 / rate_hz
        while True:
            await asyncio.sleep(period)
            with state.lock:
                urdf, urdf_version = state.urdf, state.urdf_version
            messages = []
            if urdf_version != last_urdf and urdf is not None:
                messages.append(state.robot_message())
                last_urdf = urdf_version
            text = state.frames_message()
            if text is not None and text != last_text:
                messages.append(text)
                last_text = text
            for message in messages:
                for ws, task in list(clients.items()):
                    if task is not None and not task.done():
                        with state.lock:
                            state.counts['skipped_sends'] += 1
                        continue
                    clients[ws] = asyncio.ensure_future(send(ws, message))
                if message is text:
                    with state.lock:
                        state.counts['frames_sent'] += 1

    async def start_broadcast(app):
        app['broadcast'] = asyncio.ensure_future(broadcast(app))

    async def stop_broadcast(app):
        app['broadcast'].cancel()
        for ws in list(clients):
            await ws.close()

    app = web.Application(middlewares=[guard])
    app.router.add_get('/', index)
    app.router.add_get('/app.js', app_js)
    app.router.add_get('/status', status)
    app.router.add_get('/ws', socket)
    app.router.add_get('/favicon.ico', no_icon)
    app.router.add_get(r'/mesh/{index:[0-9]+}/{name}', mesh)
    for package in VENDOR_PACKAGES:
        folder = os.path.join(root, 'node_modules', package)
        if os.path.isdir(folder):
            app.router.add_static(f'/vendor/{package}/', folder)
    app.on_startup.append(start_broadcast)
    app.on_cleanup.append(stop_broadcast)
    return app


def _good_client_message(msg, kinds):
    """Whether a page's message is one the protocol has (``{"type": "hello"}``)."""
    if msg.type != kinds.TEXT:
        return False
    try:
        data = json.loads(msg.data)
    except (ValueError, RecursionError):  # not JSON, or nested past Python's stack
        return False
    return isinstance(data, dict) and data.get('type') == 'hello'


def parse_args(argv):
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
    parser.add_argument('--package', action='append', default=[], metavar='NAME=DIR',
                        help="where package NAME is, for the URDF's package:// meshes "
                        '(repeatable; before the ament index and ROS_PACKAGE_PATH)')
    parser.add_argument('--mesh-dir', action='append', default=[], metavar='DIR',
                        help='a folder file:// meshes may be served from (repeatable; '
                        'none by default)')
    parser.add_argument('--stale-after', type=float, default=STALE_AFTER_S,
                        help='seconds without an update after which a frame is greyed')
    args = parser.parse_args(argv)
    if not (0 <= args.port <= 65535):
        parser.error(f'--port {args.port}: give 0..65535')
    if not (0 < args.rate <= 1000):
        parser.error(f'--rate {args.rate:g}: give more than 0 and at most 1000')
    if not (args.stale_after > 0):
        parser.error('--stale-after: give a positive number of seconds')
    from dq_fk_ros.description.packages import parse_package_option
    try:
        args.packages = dict(parse_package_option(option) for option in args.package)
    except ValueError as exc:
        parser.error(str(exc))
    for folder in args.mesh_dir:
        if not os.path.isdir(folder):
            parser.error(f'--mesh-dir {folder}: no such folder')
    return args


async def serve(args, state, ready=None):
    """Run the web server until SIGINT/SIGTERM; print the address to open."""
    from aiohttp import web
    bound = [] if args.host in ('0.0.0.0', '::', '') else [args.host]
    app = make_app(state, args.rate, allowed_hosts=tuple(bound + args.allow_host))
    runner = web.AppRunner(app, handle_signals=False)
    await runner.setup()
    site = web.TCPSite(runner, args.host, args.port)
    try:
        await site.start()
        host, port = runner.addresses[0][:2]
        shown = f'[{host}]' if ':' in host else host
        print(f'dq_fk_view: open http://{shown}:{port}/', flush=True)
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        await stop.wait()
    finally:
        await runner.cleanup()


def main(argv=None):
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
    state = ViewState(args.fixed_frame, args.select, args.stale_after,
                      PackageResolver(args.packages), args.mesh_dir)
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
    sys.exit(main())
