"""
The WebSocket wire as the Foxglove gate reads it: an HTTP request head, frames (RFC 6455).

:func:`parse_head` splits a request head, :func:`unmask` unmasks a client frame's payload,
:func:`frame_start` reads a server frame's head (and the request id of a Foxglove
``fetchAssetResponse``); :func:`no_repeated_keys` refuses a JSON object with a key twice.
Plain Python, no ROS.
"""

import struct

FETCH_ASSET_RESPONSE = 0x04   # the Foxglove protocol's binary opcode of an asset's answer


def parse_head(head: bytes) -> tuple:
    """Return ``(request line, [(name lower, value)], lines)`` of an HTTP request head."""
    text = head.decode('latin-1')
    lines = text.split('\r\n')
    headers = []
    for line in lines[1:]:
        if not line:
            continue
        name, sep, value = line.partition(':')
        if not sep or not name or name != name.strip():
            raise ValueError('a malformed header line')
        headers.append((name.lower(), value.strip()))
    return lines[0], headers, [line for line in lines[1:] if line]


def unmask(payload: bytes, mask: bytes) -> bytes:
    """Return a client frame's payload unmasked (RFC 6455 section 5.3)."""
    n = len(payload)
    key = (mask * (n // 4 + 1))[:n]
    return (int.from_bytes(payload, 'big') ^ int.from_bytes(key, 'big')).to_bytes(n, 'big')


def no_repeated_keys(pairs: list) -> dict:
    """Return the pairs as a dict; ``KeyError`` if a key is repeated (a JSON hook)."""
    keys = [k for k, _ in pairs]
    if len(set(keys)) != len(keys):
        raise KeyError('repeated key')
    return dict(pairs)


def frame_start(data: bytes, pos: int) -> tuple | None:
    """
    Read the head of a server frame at ``data[pos:]`` (RFC 6455 section 5.2).

    :return: ``(bytes of the whole frame, request id of a fetchAssetResponse or None)``, or
        None when ``data`` ends before the head and the first 5 payload bytes
    """
    if len(data) - pos < 2:
        return None
    length, at = data[pos + 1] & 0x7F, pos + 2
    if length == 126:
        if len(data) - at < 2:
            return None
        length, at = struct.unpack_from('>H', data, at)[0], at + 2
    elif length == 127:
        if len(data) - at < 8:
            return None
        length, at = struct.unpack_from('>Q', data, at)[0], at + 8
    request = None
    if data[pos] & 0x0F == 2 and length >= 5:
        if len(data) - at < 5:
            return None
        if data[at] == FETCH_ASSET_RESPONSE:
            request = struct.unpack_from('<I', data, at + 1)[0]
    return at - pos + length, request


__all__ = ['FETCH_ASSET_RESPONSE', 'frame_start', 'no_repeated_keys', 'parse_head', 'unmask']
