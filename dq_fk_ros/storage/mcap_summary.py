"""
An intact MCAP file's header, footer and summary, read with ``struct`` (no MCAP library).

:func:`read_summary` takes a file only if every check that rosbags' MCAP reader, the ``mcap``
library's record classes and this package's record-by-record reader make holds: the magic at
both ends, a ``ros2`` header, a 20-byte footer, a summary between the header and the footer
whose CRC holds, every record of it read exactly to its end (schemas, channels, chunk
indexes, statistics; the QoS profiles of every channel parse). Anything else raises
:class:`SummaryRefused`: the caller then reads the file as before (rosbags, or record by
record). Its records have the attribute names of the ``mcap`` library's; test_mcap_summary.py
holds them equal to the library's reading of the same files, and a refusal to a failure of
rosbags or the library.
"""

from collections import namedtuple
import os
import struct

from dq_fk_ros.storage.crc import crc32
from dq_fk_ros.storage.mcap_format import (
    MAGIC, OP_CHANNEL, OP_CHUNK_INDEX, OP_FOOTER, OP_HEADER, OP_SCHEMA, OP_STATISTICS,
    OP_SUMMARY_OFFSET)

MAX_SUMMARY_BYTES = 64 << 20    # a larger summary is left to the other readers
MAX_CHANNELS = 10_000           # channels a summary may list (each one's QoS text is parsed)

Schema = namedtuple('Schema', 'id name encoding data')
Channel = namedtuple('Channel', 'id schema_id topic message_encoding metadata')
ChunkIndex = namedtuple('ChunkIndex', 'message_start_time message_end_time chunk_start_offset '
                        'chunk_length message_index_offsets message_index_length compression '
                        'compressed_size uncompressed_size')
Summary = namedtuple('Summary', 'schemas channels chunk_index')   # id -> record, offset -> index

_U16, _U32, _U64 = struct.Struct('<H'), struct.Struct('<I'), struct.Struct('<Q')
_RECORD = struct.Struct('<BQ')
_FOOTER = struct.Struct('<BQQQI')
_CHUNK_TIMES = struct.Struct('<QQQQ')


class SummaryRefused(Exception):
    """The file is not read through its summary here; the message says why."""


class SummaryTooLarge(SummaryRefused):
    """The summary lists more channels than a bag is read with (:data:`MAX_CHANNELS`)."""


class _Fields:
    """Little-endian MCAP fields of one record body, each bound-checked."""

    def __init__(self, data, start, end):
        self.data, self.at, self.end = data, start, end

    def take(self, n):
        if n > self.end - self.at:
            raise SummaryRefused('a field runs past its record')
        self.at += n
        return self.data[self.at - n:self.at]

    def number(self, kind):
        return kind.unpack(self.take(kind.size))[0]

    def blob(self):
        return bytes(self.take(self.number(_U32)))

    def text(self):
        try:
            return self.blob().decode('utf-8')
        except UnicodeDecodeError:
            raise SummaryRefused('text that is not UTF-8') from None

    def done(self):
        if self.at != self.end:
            raise SummaryRefused('a record longer than its fields')


def _string_map(fields):
    length = fields.number(_U32)
    inner = _Fields(fields.data, fields.at, fields.at + length)
    fields.take(length)
    pairs = {}
    while inner.at < inner.end:
        key = inner.text()
        pairs[key] = inner.text()
    return pairs


def read_summary(path, qos=None) -> Summary:
    """
    Return the summary of the MCAP file ``path``; raises :class:`SummaryRefused`.

    :param qos: called with each channel's ``offered_qos_profiles`` text (an exception
        refuses the file: rosbags refuses it too).
    """
    with open(path, 'rb') as f:
        size = os.fstat(f.fileno()).st_size
        fd = f.fileno()
        head = os.pread(fd, 8 + 9 + 4 + 4, 0)
        if len(head) < 8 + 9 + 4 or head[:8] != MAGIC or head[8] != OP_HEADER:
            raise SummaryRefused('no MCAP header')
        header_end = 17 + _U64.unpack_from(head, 9)[0]
        profile_length = _U32.unpack_from(head, 17)[0]
        if profile_length != 4 or header_end > size or \
                os.pread(fd, 4, 21) != b'ros2':
            raise SummaryRefused('not the ros2 profile')
        if size < header_end + 37:
            raise SummaryRefused('no footer')
        footer_at = size - 37
        tail = os.pread(fd, 37, footer_at)
        opcode, length, summary_start, _, summary_crc = _FOOTER.unpack_from(tail)
        if tail[29:] != MAGIC or opcode != OP_FOOTER or length != 20:
            raise SummaryRefused('no footer')
        if not summary_start or not header_end <= summary_start <= footer_at or \
                footer_at - summary_start > MAX_SUMMARY_BYTES:
            raise SummaryRefused(f'no summary (or one over {MAX_SUMMARY_BYTES >> 20} MiB)')
        data = os.pread(fd, size - 4 - 8 - summary_start, summary_start)
    if summary_crc and crc32(data) != summary_crc:
        raise SummaryRefused('the summary fails its CRC')
    return _records(memoryview(data), footer_at - summary_start, qos)


def summary_intact(path) -> bool:
    """
    Whether an MCAP file's summary can be trusted: its CRC holds, or it has none to check.

    A file without a footer (cut short) has no summary and passes: readers find that out
    themselves. Raises ``OSError`` if the file cannot be read.
    """
    with open(path, 'rb') as f:
        size = os.fstat(f.fileno()).st_size
        if size < 8 + 29 + 8:
            return True
        f.seek(size - 8 - 29)
        tail = f.read(29 + 8)
        if tail[0] != OP_FOOTER or tail[29:] != MAGIC:
            return True
        summary_start, _, crc = struct.unpack_from('<QQI', tail, 9)
        if not crc or not summary_start:
            return True
        if summary_start > size - 8 - 29:
            return False
        f.seek(summary_start)
        computed, left = 0, size - 8 - 4 - summary_start
        while left > 0:  # in blocks: a footer may name a summary as long as the file
            block = f.read(min(left, 1 << 20))
            if not block:
                return False
            computed, left = crc32(block, computed), left - len(block)
        return computed == crc


def _records(data, end, qos):
    schemas, channels, chunk_index = {}, {}, {}
    pos = 0
    while pos < end:
        if end - pos < 9:
            raise SummaryRefused('a record cut off')
        opcode, length = _RECORD.unpack_from(data, pos)
        if opcode in (OP_FOOTER, OP_SUMMARY_OFFSET):   # where rosbags stops reading
            break
        if length > end - pos - 9:
            raise SummaryRefused('a record runs past the summary')
        fields = _Fields(data, pos + 9, pos + 9 + length)
        if opcode == OP_SCHEMA:
            record = Schema(fields.number(_U16), fields.text(), fields.text(), fields.blob())
            fields.done()
            if record.id in schemas:   # (readers differ on which of the two they keep)
                raise SummaryRefused(f'schema {record.id} twice')
            schemas[record.id] = record
        elif opcode == OP_CHANNEL:
            key, schema_id = fields.number(_U16), fields.number(_U16)
            record = Channel(key, schema_id, fields.text(), fields.text(), _string_map(fields))
            fields.done()
            if key in channels or (schema_id and schema_id not in schemas):
                # twice, or a schema that comes after it: rosbags reads either its own way
                raise SummaryRefused(f'channel {key} twice, or before its schema')
            if len(channels) == MAX_CHANNELS:
                raise SummaryTooLarge(f'its summary lists more than {MAX_CHANNELS} channels; '
                                      f'a bag is read with at most {MAX_CHANNELS}')
            if qos is not None and 'offered_qos_profiles' in record.metadata:
                try:
                    qos(record.metadata['offered_qos_profiles'])
                except Exception as exc:
                    raise SummaryRefused(f'QoS profiles: {type(exc).__name__}') from None
            channels[record.id] = record
        elif opcode == OP_CHUNK_INDEX:
            times = _CHUNK_TIMES.unpack(fields.take(32))
            pairs = fields.blob()
            if len(pairs) % 10:
                raise SummaryRefused('a message index map of a broken length')
            offsets = dict(struct.iter_unpack('<HQ', pairs))
            record = ChunkIndex(*times, offsets, fields.number(_U64), fields.text(),
                                fields.number(_U64), fields.number(_U64))
            fields.done()
            chunk_index[record.chunk_start_offset] = record
        elif opcode == OP_STATISTICS:
            fields.take(42)
            counts = fields.number(_U32)
            if counts % 10 or counts != fields.end - fields.at:
                raise SummaryRefused('statistics of a broken length')
        pos += 9 + length
    return Summary(schemas, channels, chunk_index)


__all__ = ['Channel', 'ChunkIndex', 'MAX_CHANNELS', 'MAX_SUMMARY_BYTES', 'read_summary',
           'Schema', 'Summary', 'summary_intact', 'SummaryRefused', 'SummaryTooLarge']
