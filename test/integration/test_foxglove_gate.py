"""
The gate before the Foxglove SDK's server (dq_fk_ros.viewers.foxglove_gate), against the real SDK.

Each test starts the SDK's server on a random loopback address and a gate before it, and
speaks raw WebSocket (RFC 6455, written here) so that it can send what a browser page, a
rebinding domain or a client that never reads would send. Where the gate makes a
difference, the same request straight to the SDK shows it.
"""

import base64
import json
import os
import resource
import socket
import struct
import threading
import time

from dq_fk_ros.testing import wait_until
from dq_fk_ros.viewers import foxglove_gate
from dq_fk_ros.viewers.foxglove_gate import Gate, private_loopback_address
import pytest

foxglove = pytest.importorskip('foxglove')  # make setup installs it (requirements/foxglove.txt)
pytestmark = pytest.mark.integration

MESH = os.urandom(2 << 20)   # a 2 MiB mesh
LEFTOVER = {}                # socket -> what came after the answer's head
SLOW = 'package://p/slow.stl'  # answered by the SDK once the test lets it


class Sdk:
    """The SDK's server on a private loopback address; counts the asset handler's calls."""

    def __init__(self):
        self.calls = 0
        self.lock = threading.Lock()
        self.release = threading.Event()   # a fetch of SLOW waits for it
        self.address = private_loopback_address()
        self.server = foxglove.start_server(name='gate-test', host=self.address, port=0,
                                            asset_handler=self.fetch)

    def fetch(self, uri):
        with self.lock:
            self.calls += 1
        if uri == SLOW:
            self.release.wait(30)
            return MESH
        return MESH if uri == 'package://p/mesh.stl' else None


@pytest.fixture
def sdk():
    server = Sdk()
    try:
        yield server
    finally:
        server.server.stop()


def start_gate(sdk, **options):
    lines = []
    gate = Gate('127.0.0.1', 0, (sdk.address, sdk.server.port),
                lambda uri: len(MESH) if uri == 'package://p/mesh.stl' else 0, lines.append,
                **options)
    gate.port = gate.start()
    gate.lines = lines
    return gate


@pytest.fixture
def gates():
    started = []
    yield started
    for gate in started:
        gate.stop()


def handshake(port, host=None, origin=None, address='127.0.0.1', extra=''):
    """Open a socket and send an upgrade request; return ``(socket, status line)``."""
    sock = socket.create_connection((address, port), timeout=20)
    key = base64.b64encode(os.urandom(16)).decode()
    head = (f'GET / HTTP/1.1\r\nHost: {host or f"127.0.0.1:{port}"}\r\nUpgrade: websocket\r\n'
            f'Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n'
            f'Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n'
            + (f'Origin: {origin}\r\n' if origin else '') + extra + '\r\n')
    sock.sendall(head.encode())
    answer = b''
    while b'\r\n\r\n' not in answer:
        part = sock.recv(4096)
        if not part:
            break
        answer += part
    head, _, LEFTOVER[sock] = answer.partition(b'\r\n\r\n')
    return sock, head.split(b'\r\n', 1)[0].decode()


def frame(payload, opcode=1, fin=True):
    """Return a masked client frame."""
    data = payload.encode() if isinstance(payload, str) else payload
    mask = os.urandom(4)
    n = len(data)
    head = bytes((0x80 * fin | opcode,))
    if n < 126:
        head += bytes((0x80 | n,))
    elif n < 1 << 16:
        head += bytes((0x80 | 126,)) + struct.pack('>H', n)
    else:
        head += bytes((0x80 | 127,)) + struct.pack('>Q', n)
    return head + mask + bytes(b ^ mask[k & 3] for k, b in enumerate(data))


def read_frames(sock, until, timeout_s=20):
    """Read server frames until ``until(frames)``; return ``[(opcode, payload)]``."""
    frames, buffer = [], LEFTOVER.pop(sock, b'')
    deadline = time.monotonic() + timeout_s
    while True:
        while len(buffer) >= 2:
            n, at = buffer[1] & 0x7F, 2
            if n == 126:
                n, at = struct.unpack('>H', buffer[2:4])[0], 4
            elif n == 127:
                n, at = struct.unpack('>Q', buffer[2:10])[0], 10
            if len(buffer) < at + n:
                break
            frames.append((buffer[0] & 0x0F, buffer[at:at + n]))
            buffer = buffer[at + n:]
        if until(frames) or time.monotonic() >= deadline:
            break
        sock.settimeout(max(0.01, deadline - time.monotonic()))
        try:
            part = sock.recv(1 << 20)
        except (TimeoutError, socket.timeout, ConnectionResetError):
            break
        if not part:
            break
        buffer += part
    if buffer:
        LEFTOVER[sock] = buffer  # the start of a frame read with the last one
    return frames


def asset_answers(frames):
    """Return ``{request id: (status, error, data length)}`` of fetchAssetResponse frames."""
    answers = {}
    for opcode, payload in frames:
        if opcode == 2 and payload[:1] == b'\x04':
            request, status, n = struct.unpack('<IBI', payload[1:10])
            answers[request] = (status, payload[10:10 + n].decode(), len(payload) - 10 - n)
    return answers


def fetch(sock, request, uri='package://p/mesh.stl'):
    sock.sendall(frame(json.dumps({'op': 'fetchAsset', 'uri': uri, 'requestId': request})))


def test_foreign_pages_and_rebinding_names_are_refused_as_the_sdk_alone_does_not(sdk, gates):
    gate = start_gate(sdk, allowed_origins=('https://robots.example',))
    gates.append(gate)
    port = gate.port
    evil = 'https://evil.example'
    # the SDK alone upgrades a foreign page and a rebinding name: why the gate stands before it
    assert '101' in handshake(sdk.server.port, origin=evil, address=sdk.address)[1]
    assert '101' in handshake(sdk.server.port, host='rebind.evil.example',
                              address=sdk.address)[1]
    for host, origin in ((None, evil), (None, 'null'), (None, 'http://evil.example:8765'),
                         ('rebind.evil.example', None), (f'rebind.evil.example:{port}', None),
                         ('localhost.evil.example', 'http://localhost:3000')):
        assert handshake(port, host=host, origin=origin)[1] == 'HTTP/1.1 403 Forbidden', \
            (host, origin)
    for host, origin in ((None, None), (None, 'https://app.foxglove.dev'),
                         (f'localhost:{port}', 'http://localhost:3000'),
                         (f'[::1]:{port}', 'file://'), ('192.168.1.20', None),
                         (None, 'https://robots.example')):
        sock, status = handshake(port, host=host, origin=origin)
        assert status.startswith('HTTP/1.1 101'), (host, origin, status)
        assert read_frames(sock, lambda frames: frames)[0][0] == 1  # the serverInfo text
        sock.close()
    assert gate.counts['refused_origins'] == 3 and gate.counts['refused_hosts'] == 3


def test_requests_that_are_no_websocket_upgrade_or_too_big_get_no_further(sdk, gates):
    gate = start_gate(sdk)
    gates.append(gate)
    sock = socket.create_connection(('127.0.0.1', gate.port), timeout=20)
    sock.sendall(b'GET /x HTTP/1.1\r\nHost: localhost\r\n\r\n')
    assert sock.recv(4096).startswith(b'HTTP/1.1 426')
    sock = socket.create_connection(('127.0.0.1', gate.port), timeout=20)
    sock.sendall(b'GET / HTTP/1.1\r\nHost: localhost\r\nX: ' + b'a' * 40_000 + b'\r\n\r\n')
    assert sock.recv(4096) == b''   # closed: a head over 16 KiB
    two = f'Host: 127.0.0.1:{gate.port}\r\n'
    assert handshake(gate.port, extra=two)[1].startswith('HTTP/1.1 400')  # Host twice


def test_half_open_connections_do_not_stop_it_listening(sdk, gates, monkeypatch):
    monkeypatch.setattr(foxglove_gate, 'HANDSHAKE_TIMEOUT_S', 2.0)
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (min(hard, 8192), hard))
    gate = start_gate(sdk, max_connections=200)
    gates.append(gate)
    idle = []
    try:
        for _ in range(1100):  # past 1024 descriptors: the SDK alone stopped listening here
            idle.append(socket.create_connection(('127.0.0.1', gate.port), timeout=20))
        assert wait_until(lambda: gate.counts.get('refused_over_limit', 0) >= 850, 20), gate.counts
        assert len(gate.connections) <= 200
        deadline = time.monotonic() + 20
        status = ''
        while time.monotonic() < deadline and not status.startswith('HTTP/1.1 101'):
            try:  # the idle ones time out after 2 s; then a client gets in
                sock, status = handshake(gate.port)
                sock.close()
            except OSError:
                time.sleep(0.2)
        assert status.startswith('HTTP/1.1 101')
        assert gate.counts['bad_handshakes'] >= 1  # idle ones were let go
    finally:
        for sock in idle:
            sock.close()
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))


def test_a_client_that_never_reads_holds_one_share_of_mesh_answers(sdk, gates):
    gate = start_gate(sdk)
    gates.append(gate)
    stalled, status = handshake(gate.port)
    assert status.startswith('HTTP/1.1 101')
    stalled.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    for request in range(400):
        fetch(stalled, request)
    # every request read by the gate: held in its queue or passed on and asked of the SDK
    connection, = gate.connections
    assert wait_until(lambda: len(connection.queued) + sdk.calls >= 400, 30), \
        (len(connection.queued), sdk.calls)
    # without the gate the SDK answers all 400 (800 MiB queued for a reader that never
    # reads); with it, 16 MiB (8 answers of 2 MiB) and what the sockets took
    assert sdk.calls <= 10, sdk.calls
    # meanwhile a client that reads gets its mesh, byte for byte
    good, _ = handshake(gate.port)
    fetch(good, 7)
    frames = read_frames(good, lambda frames: 7 in asset_answers(frames))
    answer = [p for o, p in frames if o == 2 and p[:1] == b'\x04'][0]
    assert answer[10:] == MESH
    stalled.close()
    good.close()
    deadline = time.monotonic() + 10
    while (gate.budget.used or gate.connections) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert gate.budget.used == 0   # what the stalled client held is free again


def test_a_reader_gets_every_answer_of_a_burst_in_turn(sdk, gates):
    gate = start_gate(sdk)
    gates.append(gate)
    sock, _ = handshake(gate.port)
    for request in range(30):   # 60 MiB asked at once, 16 MiB of it in flight at a time
        fetch(sock, request)
    fetch(sock, 30, 'package://p/none.stl')
    answers = asset_answers(read_frames(sock, lambda f: len(asset_answers(f)) == 31, 60))
    assert {r: answers[r] for r in range(30)} == {r: (0, '', len(MESH)) for r in range(30)}
    assert answers[30][0] == 1   # the SDK's own refusal passes through
    fetch(sock, 40, SLOW)
    fetch(sock, 40, SLOW)        # the same id while the first is held: answered at once
    frames = read_frames(sock, lambda f: sum(p[:1] == b'\x04' for _, p in f) == 1)
    refused = [asset_answers([f]).popitem()[1][:2] for f in frames if f[1][:1] == b'\x04']
    sdk.release.set()
    frames = read_frames(sock, lambda f: sum(p[:1] == b'\x04' for _, p in f) == 1)
    sock.close()
    answered = [asset_answers([f]).popitem()[1][:2] for f in frames if f[1][:1] == b'\x04']
    assert refused + answered == [(1, 'a request of this id is in flight'), (0, '')]


def test_all_clients_together_hold_at_most_the_budget(sdk, gates, monkeypatch):
    monkeypatch.setattr(foxglove_gate, 'ASSET_BYTES_IN_FLIGHT', 3 * len(MESH))
    monkeypatch.setattr(foxglove_gate, 'ASSET_BYTES_PER_CLIENT', len(MESH))
    gate = start_gate(sdk)
    gates.append(gate)
    stalled = []
    for _ in range(3):  # each asks more than the sockets between take: one answer stays held
        sock, _ = handshake(gate.port)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        for request in range(8):
            fetch(sock, request)
        stalled.append(sock)
    # the budget is full when each client holds the answer its socket cannot take
    assert wait_until(lambda: gate.budget.used == 3 * len(MESH), 20), gate.budget.used
    late, _ = handshake(gate.port)
    fetch(late, 9)
    answers = asset_answers(read_frames(late, lambda f: asset_answers(f)))
    assert answers[9][0] == 1 and 'busy' in answers[9][1]
    assert gate.counts['assets_refused'] == 1
    for sock in stalled + [late]:
        sock.close()


def test_frames_it_cannot_read_one_way_only_end_the_connection(sdk, gates):
    gate = start_gate(sdk)
    gates.append(gate)
    sock, _ = handshake(gate.port)
    read_frames(sock, lambda frames: frames)
    # keys given twice: this reader and the SDK's might take different ones
    sock.sendall(frame('{"op": "fetchAsset", "op": "subscribe", "requestId": 1, '
                       '"uri": "package://p/mesh.stl", "subscriptions": []}'))
    fetch(sock, 2)
    answers = asset_answers(read_frames(sock, lambda f: 2 in asset_answers(f)))
    assert set(answers) == {2} and gate.counts['repeated_keys'] == 1, \
        (answers, gate.counts, sdk.calls)
    sock.sendall(frame('{"op": "fetch', fin=False) + frame('Asset"}', opcode=0))
    assert read_frames(sock, lambda frames: False, timeout_s=3) == []
    assert sock.recv(10) == b''   # closed
    assert gate.counts['fragmented_frames'] == 1
    sock, _ = handshake(gate.port)
    sock.sendall(frame(b'x' * ((1 << 20) + 1), opcode=2))
    read_frames(sock, lambda frames: False, timeout_s=3)
    assert gate.counts['oversized_frames'] == 1


def test_it_says_so_in_one_line_when_its_listener_stops(sdk):
    failures = []
    gate = start_gate(sdk, on_failure=failures.append)
    try:
        gate._loop.call_soon_threadsafe(gate._server.close)
        deadline = time.monotonic() + 5
        while not failures and time.monotonic() < deadline:
            time.sleep(0.1)
        assert failures == [f'the listener on 127.0.0.1:{gate.port} stopped'] and gate.failed
        assert gate.lines == failures
    finally:
        gate.stop()
