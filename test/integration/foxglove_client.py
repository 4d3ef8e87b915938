"""
A Foxglove WebSocket client written from the protocol's specification, for the tests.

https://github.com/foxglove/ws-protocol (spec/spec.md): the client asks for the subprotocol
``foxglove.sdk.v1`` (or the older ``foxglove.websocket.v1``); the server sends JSON text
messages ``serverInfo`` and ``advertise`` (channels: id, topic, encoding, schemaName,
schema, schemaEncoding) and binary ones whose first byte is the opcode: 1 ``messageData``
(uint32 subscription id, uint64 log time, payload), 4 ``fetchAssetResponse`` (uint32
request id, uint8 status 0 success / 1 error, uint32 error length, error text, data),
all little-endian. The client sends ``subscribe`` and ``fetchAsset`` as JSON. A payload
whose encoding is ``protobuf`` is decoded with the FileDescriptorSet the channel advertises
(google.protobuf), ``cdr`` with the ``ros2msg`` definition it advertises (read by rosbags
into a type store of its own: nothing but that text says what the bytes are), ``json`` with
json. Runs on aiohttp in a thread of its own.
"""

import asyncio
import base64
import json
import struct
import threading
import time

SUBPROTOCOLS = ('foxglove.sdk.v1', 'foxglove.websocket.v1')


class FoxgloveClient:
    """One connection: channels advertised, messages per topic, asset replies."""

    def __init__(self, url):
        """Connect to ``url`` (ws://host:port) in a thread of its own."""
        self.url = url
        self.server_info = None
        self.subprotocol = None
        self.channels = {}        # id -> advertised channel
        self.messages = {}        # topic -> [(log time ns, decoded), ...]
        self.assets = {}          # request id -> (status, error, data)
        self.subscriptions = {}   # subscription id -> channel
        self.raw_frames = []      # extra frames to send (hostile tests), text or bytes
        self._decoders = {}
        self._cdr_seen = {}  # (channel id, payload) -> decoded: each payload read once
        self._loop = asyncio.new_event_loop()
        self._ws = None
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        if not self._ready.wait(20) or not wait(lambda: self.server_info, 20):
            raise AssertionError(f'no connection to {url}, or no serverInfo')

    def _run(self):
        self._loop.run_until_complete(self._main())

    async def _main(self):
        import aiohttp
        async with aiohttp.ClientSession() as session:
            async with session.ws_connect(self.url, protocols=SUBPROTOCOLS,
                                          max_msg_size=64 << 20) as ws:
                self._ws = ws
                self.subprotocol = ws.protocol
                self._ready.set()
                async for msg in ws:
                    if msg.type == aiohttp.WSMsgType.TEXT:
                        self._on_text(json.loads(msg.data))
                    elif msg.type == aiohttp.WSMsgType.BINARY:
                        self._on_binary(msg.data)
                    else:
                        break

    def _on_text(self, message):
        if message.get('op') == 'serverInfo':
            self.server_info = message
        elif message.get('op') == 'advertise':
            for channel in message['channels']:
                self.channels[channel['id']] = channel
        elif message.get('op') == 'unadvertise':
            for channel_id in message['channelIds']:
                self.channels.pop(channel_id, None)

    def _on_binary(self, data):
        opcode = data[0]
        if opcode == 1:
            subscription, log_time = struct.unpack_from('<IQ', data, 1)
            channel = self.subscriptions.get(subscription)
            if channel is not None:
                self.messages.setdefault(channel['topic'], []).append(
                    (log_time, self._decode(channel, bytes(data[13:]))))
        elif opcode == 4:
            request, status, length = struct.unpack_from('<IBI', data, 1)
            error = bytes(data[10:10 + length]).decode('utf-8', 'replace')
            self.assets[request] = (status, error, bytes(data[10 + length:]))

    def _decode(self, channel, payload):
        if channel['encoding'] == 'json':
            return json.loads(payload)
        if channel['encoding'] == 'cdr':
            # one message comes once per subscription (a bad client makes thousands): read
            # each payload once (rosbags' reader is Python; protobuf's is C)
            key = (channel['id'], payload)
            if key not in self._cdr_seen:
                if len(self._cdr_seen) > 256:
                    self._cdr_seen.clear()
                self._cdr_seen[key] = self._cdr_decoder(channel)(payload)
            return self._cdr_seen[key]
        if channel['encoding'] != 'protobuf':
            return payload
        decode = self._decoders.get(channel['id'])
        if decode is None:
            from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
            files = descriptor_pb2.FileDescriptorSet.FromString(
                base64.b64decode(channel['schema']))
            pool = descriptor_pool.DescriptorPool()
            for proto in files.file:
                pool.Add(proto)
            decode = message_factory.GetMessageClass(
                pool.FindMessageTypeByName(channel['schemaName'])).FromString
            self._decoders[channel['id']] = decode
        return decode(payload)

    def _cdr_decoder(self, channel):
        decode = self._decoders.get(channel['id'])
        if decode is None:
            from rosbags.typesys import get_types_from_msg, get_typestore, Stores
            assert channel['schemaEncoding'] == 'ros2msg', channel
            store = get_typestore(Stores.EMPTY)
            store.register(get_types_from_msg(channel['schema'], channel['schemaName']))

            msgdef = store.get_msgdef(channel['schemaName'])

            def decode(payload):
                # read as Foxglove reads it: fields in order, trailing bytes ignored (rclpy
                # may send a few more than the fields take; rosbags' own check refuses them)
                assert bytes(payload[:4]) == b'\x00\x01\x00\x00', payload[:4]
                return msgdef.deserialize_cdr_le(payload[4:], 0, msgdef.cls, store)[0]
            self._decoders[channel['id']] = decode
        return decode

    # -- requests ------------------------------------------------------------------------
    def send(self, frame, timeout_s=10):
        """Send a text (str, dict) or binary (bytes) frame as it is."""
        if isinstance(frame, dict):
            frame = json.dumps(frame)
        coroutine = self._ws.send_bytes(frame) if isinstance(frame, bytes) else \
            self._ws.send_str(frame)
        asyncio.run_coroutine_threadsafe(coroutine, self._loop).result(timeout_s)

    def channel(self, topic, timeout_s=20):
        """Return the advertised channel of ``topic``, waiting for it."""
        found = wait(lambda: next((c for c in list(self.channels.values())
                                   if c['topic'] == topic), None), timeout_s)
        assert found, (topic, sorted(c['topic'] for c in self.channels.values()))
        return found

    def subscribe(self, *topics):
        """Subscribe to the channels of ``topics`` (each advertised first)."""
        subs = []
        for topic in topics:
            channel = self.channel(topic)
            sub = len(self.subscriptions) + 1
            self.subscriptions[sub] = channel
            subs.append({'id': sub, 'channelId': channel['id']})
        self.send({'op': 'subscribe', 'subscriptions': subs})

    def fetch_asset(self, uri, timeout_s=20):
        """Return ``(status, error, data)`` of a ``fetchAsset`` of ``uri``."""
        request = len(self.assets) + 1000 + int(time.monotonic() * 1000) % 100000
        self.send({'op': 'fetchAsset', 'uri': uri, 'requestId': request})
        assert wait(lambda: request in self.assets, timeout_s), uri
        return self.assets[request]

    def close(self):
        """Close the connection and stop the thread."""
        if self._ws is not None and self._thread.is_alive():  # (the server may have closed it)
            try:
                asyncio.run_coroutine_threadsafe(self._ws.close(), self._loop).result(10)
            except Exception:
                pass
        self._thread.join(10)

    @property
    def connected(self):
        """Say whether the connection is still open."""
        return self._thread.is_alive()


def wait(predicate, timeout_s):
    """Return ``predicate()`` once it is true, or its last value after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value or time.monotonic() > deadline:
            return value
        time.sleep(0.02)
