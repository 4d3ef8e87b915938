"""
dq_fk_foxglove's front door: a TCP gate on ``--host:--port`` before the Foxglove SDK's server.

The SDK's WebSocket server (foxglove-sdk 0.30) takes any ``Host`` and ``Origin``, any number
of connections, and answers ``fetchAsset`` for a client that never reads until its queue
holds 256 meshes. It has no hook for any of that, so it listens on a random address of
127.0.0.0/8 (a page scanning loopback ports does not find it) and this gate, on the address
the user gave, passes it only what it may have:

* the HTTP request head within ``MAX_HEAD_BYTES`` and ``HANDSHAKE_TIMEOUT_S``, a WebSocket
  upgrade, ``Host`` a loopback name, an IP address, ``--host`` or an ``--allow-host`` (a page
  that points its own domain at this machine, DNS rebinding, is refused), ``Origin`` absent
  (not a browser), a loopback page, a local file, the Foxglove app (``FOXGLOVE_ORIGINS``) or
  an ``--allow-origin``; anything else gets 403 and is counted;
* at most ``max_connections`` at once (the rest are closed at once, and the gate keeps
  listening: :func:`raise_descriptor_limit` lifts the soft descriptor limit first);
* no WebSocket extension (the ``Sec-WebSocket-Extensions`` header is removed), so it reads
  the client's frames: unfragmented, at most ``MAX_CLIENT_FRAME_BYTES``;
* a ``fetchAsset`` passes while the client's answers not yet written to it hold less than
  ``ASSET_BYTES_PER_CLIENT`` (one asset always may), else it waits in the client's queue (at
  most ``MAX_QUEUED_ASSET_REQUESTS``); all clients' together hold at most
  ``ASSET_BYTES_IN_FLIGHT``, past which a request is answered with an error at once. An
  answer counts from its request until its last byte was handed to the client's socket.

What the SDK sends passes unchanged, frame by frame, as fast as the client reads it. The
gate runs an asyncio loop in a thread of its own; if its listener stops, ``on_failure`` is
called once with one line (dq_fk_foxglove then exits 1). Plain asyncio, no ROS.
The wire format (HTTP head, frames) is :mod:`.websocket_frames`.
"""

import asyncio
import ipaddress
import json
import random
import resource
import struct
import threading
import time
from urllib.parse import urlsplit

from dq_fk_ros.viewers.view_web import host_allowed, split_host
from dq_fk_ros.viewers.websocket_frames import (
    FETCH_ASSET_RESPONSE, frame_start, no_repeated_keys, parse_head, unmask)

MAX_HEAD_BYTES = 16 * 1024
HANDSHAKE_TIMEOUT_S = 10.0
MAX_CONNECTIONS = 256
MAX_CLIENT_FRAME_BYTES = 1 << 20
ASSET_BYTES_PER_CLIENT = 16 << 20
ASSET_BYTES_IN_FLIGHT = 128 << 20
MAX_QUEUED_ASSET_REQUESTS = 1024
READ_BYTES = 256 * 1024
FOXGLOVE_ORIGINS = ('https://app.foxglove.dev', 'https://studio.foxglove.dev',
                    'https://console.foxglove.dev')


def raise_descriptor_limit(wanted: int = 65536) -> int:
    """
    Raise the soft limit of open descriptors towards ``wanted`` (not past the hard one).

    :return: the soft limit now
    """
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    target = wanted if hard == resource.RLIM_INFINITY else min(wanted, hard)
    if soft != resource.RLIM_INFINITY and soft < target:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
            soft = target
        except (ValueError, OSError):
            pass
    return soft


def private_loopback_address() -> str:
    """Return a random address of 127.0.0.0/8 (not 127.0.0.1) for the SDK's server."""
    return f'127.{random.randint(1, 254)}.{random.randint(1, 254)}.{random.randint(1, 254)}'


def origin_allowed(origin: str | None, allowed=()) -> bool:
    """
    Whether a WebSocket ``Origin`` may connect: see the module doc.

    :param allowed: more origins, exactly as a browser sends them (``--allow-origin``)
    :return: True for an allowed or absent origin
    """
    if origin is None or origin in FOXGLOVE_ORIGINS or origin in allowed:
        return True
    try:
        parts = urlsplit(origin)
        host = parts.hostname or ''
    except ValueError:
        return False
    if parts.scheme == 'file':
        return True
    return parts.scheme in ('http', 'https') and host_allowed(host)


def request_host_allowed(host_header: str, allowed=()) -> bool:
    """Whether a ``Host`` header may reach the server: see the module doc."""
    host = split_host(host_header)
    if host_allowed(host, allowed):
        return True
    try:
        ipaddress.ip_address(host.strip('[]'))  # an address cannot be rebound
        return True
    except ValueError:
        return False


class Budget:
    """Asset bytes in flight for all clients (used on the gate's loop only)."""

    def __init__(self, total: int):
        """Allow ``total`` bytes (one asset of any size while nothing else is in flight)."""
        self.total = total
        self.used = 0

    def fits(self, size: int) -> bool:
        """Return whether ``size`` more bytes may go in flight."""
        return self.used == 0 or self.used + size <= self.total


class Connection:
    """One client: its handshake, its frames both ways, its asset requests."""

    def __init__(self, gate, reader, writer):
        """Take the client's streams; nothing is read yet."""
        self.gate = gate
        self.reader = reader
        self.writer = writer
        self.up_writer = None
        self.in_flight = {}      # request id -> bytes reserved
        self.queued = []         # (request id, size, raw frame) waiting for the client's share
        self.pending_out = []    # frames made here, sent at the next frame boundary
        self.at_boundary = True  # what went to the client ends with a whole frame

    # -- the handshake --------------------------------------------------------------------
    async def run(self) -> None:
        """Check the handshake, connect to the SDK, pass frames until either side closes."""
        gate = self.gate
        try:
            head = await asyncio.wait_for(self.reader.readuntil(b'\r\n\r\n'),
                                          HANDSHAKE_TIMEOUT_S)
        except (asyncio.TimeoutError, asyncio.LimitOverrunError, asyncio.IncompleteReadError,
                ConnectionError):
            gate.count('bad_handshakes')
            return
        refusal = self.refusal(head)
        if refusal:
            status, what = refusal
            gate.count(what)
            body = what.replace('_', ' ') + '\n'
            self.writer.write(f'HTTP/1.1 {status}\r\nContent-Type: text/plain\r\n'
                              f'Content-Length: {len(body)}\r\nConnection: close\r\n\r\n'
                              f'{body}'.encode())
            return
        try:
            up_reader, self.up_writer = await asyncio.open_connection(*gate.upstream,
                                                                      limit=READ_BYTES)
        except OSError as exc:
            gate.fail(f'the Foxglove SDK server on {gate.upstream[0]}:{gate.upstream[1]} '
                      f'refused a connection: {exc}')
            return
        self.up_writer.write(self.forwarded_head)
        down = asyncio.ensure_future(self.server_to_client(up_reader))
        up = asyncio.ensure_future(self.client_to_server())
        await asyncio.wait((down, up), return_when=asyncio.FIRST_COMPLETED)
        for task in (down, up):
            task.cancel()
        await asyncio.gather(down, up, return_exceptions=True)

    def refusal(self, head: bytes) -> tuple | None:
        """Return ``(HTTP status, counter)`` if the request may not pass, else None."""
        try:
            request_line, headers, lines = parse_head(head[:-4])
        except (ValueError, UnicodeError):
            return '400 Bad Request', 'bad_requests'
        names = [n for n, _ in headers]
        values = dict(headers)
        if names.count('host') != 1 or names.count('origin') > 1 or \
                not request_line.startswith('GET '):
            return '400 Bad Request', 'bad_requests'
        if 'websocket' not in values.get('upgrade', '').lower():
            return '426 Upgrade Required', 'not_websocket'
        if not request_host_allowed(values['host'], self.gate.allowed_hosts):
            return '403 Forbidden', 'refused_hosts'
        if not origin_allowed(values.get('origin'), self.gate.allowed_origins):
            return '403 Forbidden', 'refused_origins'
        kept = [line for line in lines
                if not line.lower().startswith('sec-websocket-extensions')]
        self.forwarded_head = '\r\n'.join([request_line, *kept, '', '']).encode('latin-1')
        return None

    # -- client -> SDK --------------------------------------------------------------------
    async def client_to_server(self) -> None:
        """Pass the client's frames on; hold ``fetchAsset`` to the budget (module doc)."""
        read = self.reader.readexactly
        while True:
            head = await read(2)
            opcode, length = head[0] & 0x0F, head[1] & 0x7F
            if head[0] & 0x70 or not head[1] & 0x80:
                self.gate.count('bad_frames')
                return  # an extension bit (none was agreed) or an unmasked frame
            if not head[0] & 0x80 or opcode == 0:
                self.gate.count('fragmented_frames')
                return  # fragmented: not sent by browsers, not read here
            if length == 126:
                extra = await read(2)
                length = struct.unpack('>H', extra)[0]
            elif length == 127:
                extra = await read(8)
                length = struct.unpack('>Q', extra)[0]
            else:
                extra = b''
            if length > MAX_CLIENT_FRAME_BYTES:
                self.gate.count('oversized_frames')
                return
            mask = await read(4)
            payload = await read(length)
            frame = head + extra + mask + payload
            if opcode == 1 and self.hold_asset_request(frame, mask, payload):
                continue
            self.up_writer.write(frame)
            await self.up_writer.drain()

    def hold_asset_request(self, frame, mask, payload) -> bool:
        """Queue, refuse or reserve a ``fetchAsset`` text frame; True if not to pass now."""
        try:
            message = json.loads(unmask(payload, mask), object_pairs_hook=no_repeated_keys)
        except (ValueError, RecursionError):
            return False  # the SDK's to refuse: it is no request
        except KeyError:
            self.gate.count('repeated_keys')
            return True   # read one way here and maybe another by the SDK: dropped
        if not isinstance(message, dict) or message.get('op') != 'fetchAsset':
            return False
        request = message.get('requestId')
        uri = message.get('uri')
        if type(request) is not int or not 0 <= request < 1 << 32 or not isinstance(uri, str):
            return False  # the SDK's to refuse
        if request in self.in_flight or any(q[0] == request for q in self.queued):
            self.answer_error(request, 'a request of this id is in flight')
            return True
        size = self.gate.asset_size(uri)
        if self.queued or not self.fits(size):
            if len(self.queued) >= MAX_QUEUED_ASSET_REQUESTS:
                self.answer_error(request, 'too many asset requests waiting')
            else:
                self.queued.append((request, size, frame))
            return True
        if not self.gate.budget.fits(size):
            self.gate.count('assets_refused')
            self.answer_error(request, 'the server is busy sending assets: fetch it again')
            return True
        self.reserve(request, size)
        return False

    def fits(self, size) -> bool:
        used = sum(self.in_flight.values())
        return not self.in_flight or used + size <= ASSET_BYTES_PER_CLIENT

    def reserve(self, request, size) -> None:
        self.in_flight[request] = size
        self.gate.budget.used += size

    def release(self, request) -> None:
        """Free the bytes of an answer handed to the client; pass what waited for them."""
        self.gate.budget.used -= self.in_flight.pop(request, 0)
        while self.queued and self.fits(self.queued[0][1]):
            request, size, frame = self.queued.pop(0)
            if not self.gate.budget.fits(size):
                self.gate.count('assets_refused')
                self.answer_error(request, 'the server is busy sending assets: fetch it again')
                continue
            self.reserve(request, size)
            self.up_writer.write(frame)

    def answer_error(self, request, error) -> None:
        """Send the client a ``fetchAssetResponse`` error (at a frame boundary)."""
        text = error.encode()
        payload = struct.pack('<BIBI', FETCH_ASSET_RESPONSE, request, 1, len(text)) + text
        frame = bytes((0x82, len(payload))) + payload  # under 126 bytes
        if self.at_boundary:
            self.writer.write(frame)
        else:
            self.pending_out.append(frame)

    # -- SDK -> client --------------------------------------------------------------------
    async def server_to_client(self, up) -> None:
        """Pass the SDK's answer head, then its frames, as fast as the client takes them."""
        head = await up.readuntil(b'\r\n\r\n')
        self.writer.write(head)
        await self.writer.drain()
        if not head.startswith(b'HTTP/1.1 101'):
            return
        carry = b''       # the start of a frame too short to read its head yet
        remaining = 0     # bytes of the current frame not yet read
        current = None    # its request id, if it is a fetchAssetResponse
        while True:
            data = await up.read(READ_BYTES)
            if not data:
                return
            data, pos, done = carry + data, 0, []
            while pos < len(data):
                if remaining:
                    step = min(remaining, len(data) - pos)
                    pos, remaining = pos + step, remaining - step
                    if not remaining and current is not None:
                        done.append(current)
                    continue
                start = frame_start(data, pos)
                if start is None:
                    break     # wait for the rest of its head
                size, current = start
                remaining = size
            carry = data[pos:]
            self.writer.write(data[:pos])
            self.at_boundary = not remaining
            if self.at_boundary:
                for frame in self.pending_out:
                    self.writer.write(frame)
                self.pending_out.clear()
            await self.writer.drain()
            for request in done:
                self.release(request)

    def close(self) -> None:
        """Free what this client held; close both sockets."""
        for request in list(self.in_flight):
            self.gate.budget.used -= self.in_flight.pop(request)
        self.queued.clear()
        for writer in (self.writer, self.up_writer):
            if writer is not None:
                writer.close()


class Gate:
    """The listener before the SDK's server (module doc); its asyncio loop in a thread."""

    def __init__(self, host: str, port: int, upstream: tuple, asset_size, log,
                 allowed_hosts=(), allowed_origins=(), on_failure=None,
                 max_connections: int | None = None):
        """
        Prepare a gate; :meth:`start` binds it.

        :param upstream: ``(address, port)`` of the SDK's server
        :param asset_size: ``uri -> bytes`` an answer to ``fetchAsset(uri)`` will hold (0 if
            none)
        :param log: called with one line per event worth a line
        :param on_failure: called once, with one line, if the listener stops
        """
        self.host, self.port, self.upstream = host, port, upstream
        self.asset_size = asset_size
        self.log = log
        self.allowed_hosts = tuple(allowed_hosts) + (host,)
        self.allowed_origins = tuple(allowed_origins)
        self.on_failure = on_failure
        limit = raise_descriptor_limit()
        fit = max(8, (limit - 128) // 3)   # a client, its SDK side and the gate's own
        self.max_connections = min(max_connections or MAX_CONNECTIONS, fit)
        self.budget = Budget(ASSET_BYTES_IN_FLIGHT)
        self.counts = {}
        self.connections = set()
        self.failed = None
        self._logged_at = {}
        self._loop = asyncio.new_event_loop()
        self._server = None
        self._thread = None

    def count(self, what) -> None:
        """Count an event; log it at most once every 10 s."""
        self.counts[what] = self.counts.get(what, 0) + 1
        now = time.monotonic()
        if now - self._logged_at.get(what, -1e9) >= 10.0:
            self._logged_at[what] = now
            self.log(f'{what.replace("_", " ")}: {self.counts[what]} so far')

    def fail(self, line) -> None:
        """Report the gate unusable, once."""
        if self.failed is None:
            self.failed = line
            self.log(line)
            if self.on_failure is not None:
                self.on_failure(line)

    def start(self) -> int:
        """Bind and listen; return the port (raises OSError when it cannot)."""
        self._server = self._loop.run_until_complete(asyncio.start_server(
            self._accept, self.host, self.port, limit=MAX_HEAD_BYTES, backlog=512,
            reuse_address=True))
        self._loop.set_exception_handler(self._loop_exception)
        self._thread = threading.Thread(target=self._run, name='dq_fk_foxglove gate',
                                        daemon=True)
        self._thread.start()
        self.port = self._server.sockets[0].getsockname()[1]
        return self.port

    def _run(self):
        try:
            self._loop.create_task(self._watch())
            self._loop.run_forever()
        except BaseException as exc:  # the loop itself broke
            self.fail(f'the listener stopped: {exc!r}'[:300])

    async def _watch(self):
        while True:
            await asyncio.sleep(1.0)
            if not self._server.is_serving():
                self.fail(f'the listener on {self.host}:{self.port} stopped')
                return

    def _loop_exception(self, loop, context):
        self.count('loop_errors')  # e.g. accept() at the descriptor limit (it retries)

    async def _accept(self, reader, writer):
        if len(self.connections) >= self.max_connections:
            self.count('refused_over_limit')
            writer.close()
            return
        writer.transport.set_write_buffer_limits(high=1 << 20)
        connection = Connection(self, reader, writer)
        self.connections.add(connection)
        try:
            await connection.run()
        except (ConnectionError, asyncio.IncompleteReadError, asyncio.LimitOverrunError,
                OSError):
            pass
        except Exception:  # nothing a client sends may stop the gate
            self.count('connection_errors')
        finally:
            self.connections.discard(connection)
            connection.close()

    def stop(self) -> None:
        """Close the listener and every connection; stop the loop."""
        if self._thread is None:
            return

        async def shut():
            self._server.close()
            for connection in list(self.connections):
                connection.close()
        asyncio.run_coroutine_threadsafe(shut(), self._loop).result(5)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(5)


__all__ = ['ASSET_BYTES_IN_FLIGHT', 'ASSET_BYTES_PER_CLIENT', 'FOXGLOVE_ORIGINS', 'Gate',
           'HANDSHAKE_TIMEOUT_S', 'MAX_CONNECTIONS', 'origin_allowed',
           'private_loopback_address', 'raise_descriptor_limit', 'request_host_allowed']
