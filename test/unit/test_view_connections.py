"""dq_fk_view's connection limits: who gives up a place when the server is full."""

import asyncio

from dq_fk_ros.viewers.view import Connections, GuardedProtocol


class FakeTransport:
    def __init__(self):
        self.aborted = False

    def abort(self):
        self.aborted = True


class FakeHandler:
    def __init__(self):
        self.made = self.lost = 0
        self.data = b''

    def connection_made(self, transport):
        self.made += 1

    def data_received(self, data):
        self.data += data

    def connection_lost(self, exc):
        self.lost += 1


def connect(connections, loop, first_bytes=b''):
    proto = GuardedProtocol(FakeHandler(), loop, connections)
    proto.connection_made(FakeTransport())
    if first_bytes:
        proto.data_received(first_bytes)
    return proto


def test_a_full_server_drops_half_sent_requests_first_then_plain_http_never_a_page():
    loop = asyncio.new_event_loop()
    try:
        counts = {}
        connections = Connections(counts, cap=4)
        page = connect(connections, loop, b'GET /ws HTTP/1.1\r\nUpgrade: websocket\r\n\r\n')
        plain = connect(connections, loop, b'GET / HTTP/1.1\r\nHost: x\r\n\r\n')
        slow = [connect(connections, loop, b'GET / HTTP/1.1\r\nHo') for _ in range(2)]
        assert len(connections.open) == 4
        newcomer = connect(connections, loop, b'GET /status HTTP/1.1\r\n\r\n')
        assert slow[0].transport.aborted and not slow[1].transport.aborted
        assert slow[0].inner.lost == 1 and not newcomer.transport.aborted
        blank = connect(connections, loop)  # nothing sent yet: still in its headers
        assert slow[1].transport.aborted
        third = connect(connections, loop, b'GET /a HTTP/1.1\r\n\r\n')
        assert blank.transport.aborted and not plain.transport.aborted
        fourth = connect(connections, loop, b'GET /b HTTP/1.1\r\n\r\n')
        assert plain.transport.aborted and not page.transport.aborted  # oldest plain HTTP
        assert not third.transport.aborted and not fourth.transport.aborted
        assert counts['evicted_connections'] == 4 and len(connections.open) == 4
        full = Connections({}, cap=1)
        connect(full, loop, b'GET /ws HTTP/1.1\r\nupgrade: WebSocket\r\n\r\n')
        refused = connect(full, loop)
        assert refused.transport.aborted and refused.inner.made == 0
        assert full.counts['refused_connections'] == 1
        for proto in list(connections.open):  # a place is freed once, however it ends
            proto.connection_lost(None)
            proto.connection_lost(None)
        assert connections.open == {}
    finally:
        loop.close()


def test_the_header_clock_drops_a_connection_that_never_ends_its_headers(monkeypatch):
    import dq_fk_ros.viewers.view as view
    monkeypatch.setattr(view, 'HEADER_TIMEOUT_S', 0.05)
    loop = asyncio.new_event_loop()
    try:
        counts = {}
        connections = Connections(counts, cap=10)
        slow = connect(connections, loop, b'GET / HTTP/1.1\r\n')
        done = connect(connections, loop, b'GET / HTTP/1.1\r\n\r\n')
        # asyncio runs due timers in deadline order, however late: the 0.05 s one first
        loop.run_until_complete(asyncio.sleep(0.2))
        assert slow.transport.aborted and not done.transport.aborted
        assert counts == {'slow_requests': 1} and list(connections.open) == [done]
    finally:
        loop.close()
