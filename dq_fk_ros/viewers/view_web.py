"""
dq_fk_view's web server (aiohttp): the page, its scripts, the meshes, /status and /ws.

Only this machine's pages get anything: every request must name a loopback host (or the
address the server listens on, or one given with ``--allow-host``) in its ``Host`` header,
so a web page that points its own domain at 127.0.0.1 (DNS rebinding) is refused; and a
WebSocket whose ``Origin`` is not the server's own is refused (another site's page open in
the same browser). Both answer 403. Messages from pages are read and, but for
``{"type": "hello"}`` and, with the joint panel (``--joint-panel``), ``{"type": "joints",
...}`` (:class:`~dq_fk_ros.viewers.view_panel.JointPanel` checks it), ignored; anything else
(not JSON, binary, too big, nested too deeply, joints without a panel) is counted in
``/status``.
"""

import asyncio
import ipaddress
import json
import os
from typing import TYPE_CHECKING

from dq_fk_ros.description.meshes import read_mesh_file
from dq_fk_ros.description.shipped import share_folders

if TYPE_CHECKING:  # aiohttp is imported where used
    from aiohttp import web

DEFAULT_RATE_HZ = 30.0
MAX_CLIENT_MESSAGE_BYTES = 64 * 1024
CLOSE_TIMEOUT_S = 2.0  # on stop: how long open pages get to answer the WebSocket close
LOOPBACK_NAMES = ('localhost', 'localhost.localdomain', 'ip6-localhost')
VENDOR_PACKAGES = ('three', 'urdf-loader')


def web_root() -> str:
    """Return the folder of the page (``web/``: installed share directory, or source tree)."""
    candidates = share_folders('web')
    pages = [f for f in candidates if os.path.isfile(os.path.join(f, 'index.html'))]
    for folder in pages:  # one with three.js and urdf-loader installed (npm ci) first
        if os.path.isdir(os.path.join(folder, 'node_modules', 'three')):
            return folder
    if pages:
        return pages[0]
    raise FileNotFoundError(f'the page of dq_fk_view is not in {" or ".join(candidates)}')


def host_allowed(host, allowed=()) -> bool:
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


def split_host(value: str) -> str:
    """Return the host of a ``Host`` header value (``name``, ``name:port``, ``[v6]:port``)."""
    value = value.strip()
    if value.startswith('['):
        return value[1:value.find(']')] if ']' in value else ''
    return value.rsplit(':', 1)[0] if value.count(':') == 1 else value


def make_app(state, rate_hz=DEFAULT_RATE_HZ, root=None, allowed_hosts=()) -> 'web.Application':
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
        if not host_allowed(split_host(request.headers.get('Host', '')), allowed_hosts):
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
        try:  # opened once, checked and read by its descriptor (not reopened by name)
            data = await asyncio.get_running_loop().run_in_executor(None, read_mesh_file, path)
        except ValueError:
            with state.lock:
                state.counts['refused_meshes'] = state.counts.get('refused_meshes', 0) + 1
            return web.Response(status=404, text='not found\n')
        return web.Response(body=data, headers={'Content-Type': kind})

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
                kind = _client_message(msg, WSMsgType)
                taken = kind == 'hello' or (kind is not None and state.panel is not None
                                            and state.panel.take_page(kind))
                if not taken:
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

    async def close_pages(app):
        # on_shutdown, before aiohttp waits for handlers: an open page holds its handler
        app['broadcast'].cancel()
        closing = [ws.close() for ws in list(clients)]
        if closing:  # a page that never answers the close holds the stop CLOSE_TIMEOUT_S
            await asyncio.wait([asyncio.ensure_future(c) for c in closing],
                               timeout=CLOSE_TIMEOUT_S)

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
    app.on_shutdown.append(close_pages)
    return app


def _client_message(msg, kinds):
    """
    Return a page's message the protocol has: ``'hello'``, or a ``joints`` message's dict.

    None for anything else (binary, not JSON, another type).
    """
    if msg.type != kinds.TEXT:
        return None
    try:
        data = json.loads(msg.data)
    except (ValueError, RecursionError):  # not JSON, or nested past Python's stack
        return None
    if not isinstance(data, dict):
        return None
    if data.get('type') == 'hello':
        return 'hello'
    return data if data.get('type') == 'joints' else None


__all__ = ['DEFAULT_RATE_HZ', 'host_allowed', 'make_app', 'web_root']
