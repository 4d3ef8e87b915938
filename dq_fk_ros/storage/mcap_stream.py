"""
MCAP files read record by record: bags rosbags cannot open, or cannot read to the end.

``ros2 bag record`` writes ``metadata.yaml`` and the MCAP summary and footer when it stops;
a recording killed on the robot (power lost, SIGKILL) has neither, and rosbags refuses the
bag. A damaged byte inside a chunk makes rosbags stop at that chunk. :class:`McapStreamBag`
reads such files itself, with Foxglove's ``mcap`` record classes, in file order:

* every chunk is checked (CRC, structure); a damaged chunk is skipped and reported with the
  number of messages it held (from its message indexes, where they survive);
* after a damaged record the reader resynchronises on the next chunk whose structure and CRC
  are intact (from the summary's chunk index where the summary is intact, else by scanning),
  so one damaged byte costs one chunk, not the rest of the file;
* channels and schemas come from the data section and, where its CRC holds, the summary.

It is a :class:`~dq_fk_ros.storage.reader_interface.BagReader` (:func:`open_stream_bag`),
and says in
:attr:`McapStreamBag.damage` what was skipped.
"""

from collections import Counter
from io import BytesIO
import mmap
import os
import re
import struct
from typing import Iterator
import zlib

from dq_fk_ros.errors import BagError
from dq_fk_ros.storage.decompress import ChunkRefused, decompress_chunk
from dq_fk_ros.storage.mcap_format import (
    MAGIC, OP_CHANNEL, OP_CHUNK, OP_CHUNK_INDEX, OP_DATA_END, OP_FOOTER,
    OP_HEADER, OP_MESSAGE, OP_MESSAGE_INDEX, OP_METADATA, OP_SCHEMA)
from dq_fk_ros.storage.reader_interface import BatchesFromMessages
from dq_fk_ros.storage.rosbag2_metadata import parse_qos
from dq_fk_ros.storage.text import printable
from rosbags.interfaces import (
    Connection, ConnectionExtRosbag2, MessageDefinition, MessageDefinitionFormat)

END_LENGTHS = {OP_DATA_END: 4, OP_FOOTER: 20}   # the body sizes of the records that end data
# what a resynchronisation looks for, and how an intact schema or channel record looks
_CANDIDATE = re.compile(rb'[\x03\x04\x06]')
_NAME = re.compile(r'[A-Za-z0-9_]+(/[A-Za-z0-9_]+)*')
_TOPIC = re.compile(r'/?[A-Za-z0-9_~{}]+(/[A-Za-z0-9_{}]+)*')
MAX_DAMAGE_LINES = 3            # damaged parts described in full; the rest are counted
MAX_DAMAGE_LINE = 300           # characters of one description
MAX_DEFINITION_BYTES = 1 << 20  # a schema or channel record found by a resync is smaller
SCHEMA_ENCODINGS = ('ros2msg', 'ros2idl', 'ros1msg', 'omgidl', 'jsonschema', 'protobuf',
                    'flatbuffer')
MESSAGE_ENCODINGS = ('cdr', 'ros1', 'json', 'protobuf', 'flatbuffer', 'cbor', 'msgpack')
_U64 = struct.Struct('<Q')
_CHUNK_HEAD = struct.Struct('<QQQII')  # start, end, uncompressed size, crc, compression len


def open_stream_bag(files, path, why) -> 'McapStreamBag':
    """
    Open MCAP ``files`` (of the bag ``path``) record by record; ``why``: rosbags could not.

    ``why`` None: a bare ``.mcap`` file, read this way by choice (no note). Raises
    :class:`~dq_fk_ros.errors.BagError` if a file cannot be opened.
    """
    listing = ', '.join(os.path.basename(f) for f in files)
    note = None if why is None else \
        f'{path}: not a complete rosbag2 ({why}); read {listing} record by record'
    try:
        return McapStreamBag(files, note)
    except OSError as exc:
        raise BagError(f'{path}: cannot be read ({exc})') from None


class McapStreamBag(BatchesFromMessages):
    """
    The messages of one or more MCAP files, read in file order (no index needed).

    Opening scans the files once: channels, message counts, first time and what is damaged.
    :meth:`messages` reads them again, skipping the same damaged parts.

    :param paths: MCAP files, read in this order (the splits of one recording).
    :param note: one line for the user on why the bag is read this way, or None.
    """

    copies_messages = True
    windowable = False

    def __init__(self, paths, note=None):
        """Scan ``paths``; raises ``OSError`` if a file cannot be opened."""
        self.paths = [os.fspath(p) for p in paths]
        self.note = note            # one line for the user about how the bag is read
        for path in self.paths:
            with open(path, 'rb'):
                pass
        self.connections = []
        self._by_channel = {}       # (file index, channel id) -> Connection
        self.damage = None          # one line: what was damaged and skipped, or None
        counts = Counter()
        self.start_time = None      # earliest log time (ns), as rosbags' Reader.start_time
        self.end_time = 0           # past the latest log time (ns), as rosbags' end_time
        for conn_id, _, log_time in self._records(scanning=True):
            counts[conn_id] += 1
            if self.start_time is None or log_time < self.start_time:
                self.start_time = log_time
            self.end_time = max(self.end_time, log_time + 1)
        self.start_time = self.start_time or 0
        self.connections = [c._replace(msgcount=counts[c.id]) for c in self.connections]
        self._by_id = {c.id: c for c in self.connections}
        self._by_channel = {key: self._by_id[c.id] for key, c in self._by_channel.items()}
        self.all_topics = [(c.topic, c.msgtype) for c in self.connections]

    def fallback(self) -> None:
        """Nothing to fall back to: this reader already skips damage."""
        return None

    def close(self) -> None:
        """Do nothing: every pass closes its file."""

    def messages(self, connections=None, start=None, stop=None) -> Iterator[tuple]:
        """
        Yield ``(connection, log_time_ns, raw)`` in file order, skipping damaged chunks.

        :param connections: only these connections (default all).
        :param start: only log times ``>= start`` ns; ``stop``: only ``< stop``.
        """
        wanted = None if connections is None else {c.id for c in connections}
        for conn_id, data, log_time in self._records():
            if (wanted is None or conn_id in wanted) and (start is None or log_time >= start) \
                    and (stop is None or log_time < stop):
                yield self._by_id[conn_id], log_time, data

    # -- the two passes: scanning builds the connections and finds the damage -------------
    def _records(self, scanning=False):
        for file_index, path in enumerate(self.paths):
            with open(path, 'rb') as f:
                size = os.fstat(f.fileno()).st_size
                if size == 0:
                    if scanning:
                        self._report(f'{path} is empty')
                    continue
                with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as data:
                    yield from self._file_records(file_index, path, data, scanning)

    def _file_records(self, file_index, path, data, scanning):
        from mcap.records import Channel, Schema
        reader = _RecordReader(data)
        schemas = dict(reader.summary_schemas)
        local = {}
        orphans = 0
        for channel in reader.summary_channels.values():
            local[channel.id] = self._channel(file_index, channel, schemas, scanning).id
        for kind, item in reader.records():
            if kind == 'damage':
                if scanning:
                    self._report(f'{path} {item}')
            elif kind == 'damaged_chunk':
                offset, why, per_channel = item
                if scanning:
                    self._damaged_chunk(path, offset, why, per_channel, file_index, local)
            elif isinstance(item, Schema):
                schemas[item.id] = item
            elif isinstance(item, Channel):
                if item.id not in local:
                    local[item.id] = self._channel(file_index, item, schemas, scanning).id
            elif item.channel_id in local:  # a message
                yield local[item.channel_id], item.data, item.log_time
            else:
                orphans += 1
        if orphans and scanning:
            self._report(f'{path}: {orphans} messages on channels whose definition is lost '
                         f'to damage; skipped')

    def _damaged_chunk(self, path, offset, why, per_channel, file_index, local):
        if per_channel is None:
            held = 'an unknown number of messages (its message indexes are damaged too)'
        else:
            topics = Counter()
            for channel_id, count in per_channel.items():
                conn = self._by_channel.get((file_index, channel_id))
                topics[conn.topic if conn is not None else f'channel {channel_id}'] += count
            held = f'{sum(topics.values())} messages (' + ', '.join(
                f'{printable(topic)}: {n}' for topic, n in sorted(topics.items())) + ')'
        self._report(f'{path}: the chunk at byte {offset} is damaged ({why}); skipped {held}')

    def _report(self, line):
        """Add a line to :attr:`damage`: the first few whole, the rest counted (one line)."""
        self._reports = getattr(self, '_reports', 0) + 1
        if self._reports <= MAX_DAMAGE_LINES:
            line = line if len(line) <= MAX_DAMAGE_LINE else line[:MAX_DAMAGE_LINE - 3] + '...'
            self.damage = '; '.join(filter(None, [self.damage, line]))
            self._shown = self.damage
        else:
            self.damage = f'{self._shown}; and {self._reports - MAX_DAMAGE_LINES} more ' \
                          f'damaged parts skipped'

    def _channel(self, file_index, channel, schemas, scanning):
        key = (file_index, channel.id)
        if not scanning:
            return self._by_channel[key]
        return self._connection(file_index, channel, schemas)

    def _connection(self, file_index, channel, schemas):
        """Return the connection of a channel (one per topic and type across the files)."""
        key = (file_index, channel.id)
        if key in self._by_channel:
            return self._by_channel[key]
        schema = schemas.get(channel.schema_id)
        msgtype = schema.name if schema is not None else ''
        for conn in self.connections:
            if (conn.topic, conn.msgtype) == (channel.topic, msgtype):
                self._by_channel[key] = conn
                return conn
        fmt = MessageDefinitionFormat.IDL if schema is not None and \
            schema.encoding == 'ros2idl' else MessageDefinitionFormat.MSG
        definition = schema.data.decode('utf-8', 'replace') if schema is not None else ''
        qos_text = channel.metadata.get('offered_qos_profiles', '')
        try:
            qos = parse_qos(qos_text) if qos_text else []
        except Exception:  # a profile rosbags cannot parse: copy without one
            qos = []
        conn = Connection(id=len(self.connections) + 1, topic=channel.topic, msgtype=msgtype,
                          msgdef=MessageDefinition(fmt, definition),
                          digest=channel.metadata.get('topic_type_hash', ''), msgcount=0,
                          ext=ConnectionExtRosbag2(channel.message_encoding, qos), owner=self)
        self.connections.append(conn)
        self._by_channel[key] = conn
        return conn


class _DamagedRecord(Exception):
    """A record whose framing or content cannot be trusted."""


class _RecordReader:
    """
    The records of one MCAP file in memory (an mmap), tolerant of damage.

    :meth:`records` yields ``('record', record)`` for schemas, channels and messages (those
    of intact chunks too), ``('damaged_chunk', (offset, why, {channel: count} or None))``
    and ``('damage', line)``.
    """

    def __init__(self, data):
        """Read the summary if the footer and the summary's CRC are intact."""
        self.data = data
        self.size = len(data)
        self.summary_schemas, self.summary_channels = {}, {}
        self.chunk_index = {}       # chunk start offset -> ChunkIndex, from an intact summary
        self.summary_start = None
        try:
            self._read_summary()
        except Exception:  # no usable summary (cut short, damaged): read without it
            self.summary_schemas, self.summary_channels, self.chunk_index = {}, {}, {}
            self.summary_start = None

    # -- parsing one record --------------------------------------------------------------
    def _frame(self, pos):
        """Return ``(opcode, body start, end)`` of the record at ``pos``, or raise."""
        if pos + 9 > self.size:
            raise _DamagedRecord(f'the file ends inside a record at byte {pos}')
        opcode = self.data[pos]
        length = _U64.unpack_from(self.data, pos + 1)[0]
        end = pos + 9 + length
        if opcode == 0:   # the spec's invalid opcode; others unknown here are skipped, as
            raise _DamagedRecord(f'record type 0x00 at byte {pos}')   # rosbags and mcap do
        if end > self.size:
            raise _DamagedRecord(f'the record at byte {pos} runs past the end of the file')
        return opcode, pos + 9, end

    def _parse(self, opcode, start, end, kind):
        """Parse the body with mcap's record class; the body must be used exactly."""
        from mcap.data_stream import ReadDataStream
        stream = ReadDataStream(BytesIO(self.data[start:end]))
        record = kind.read(stream, end - start) if opcode == OP_MESSAGE else kind.read(stream)
        if stream.count != end - start:
            raise _DamagedRecord(f'record at byte {start - 9} has {end - start} bytes, '
                                 f'its fields {stream.count}')
        return record

    def _read_summary(self):
        from mcap.records import Channel, ChunkIndex, Footer, Schema
        data, size = self.data, self.size
        if size < 8 + 29 + 8 or data[size - 8:] != MAGIC:
            return
        footer_at = size - 8 - 29
        if data[footer_at] != OP_FOOTER:
            return
        footer = self._parse(OP_FOOTER, footer_at + 9, size - 8, Footer)
        start = footer.summary_start
        if not start or not 8 <= start <= footer_at:
            return
        # the summary CRC covers the summary section and the footer up to the CRC field
        if footer.summary_crc and zlib.crc32(data[start:size - 8 - 4]) != footer.summary_crc:
            return
        kinds = {OP_SCHEMA: Schema, OP_CHANNEL: Channel, OP_CHUNK_INDEX: ChunkIndex}
        pos = start
        while pos < footer_at:
            opcode, body, end = self._frame(pos)
            if opcode in kinds:
                record = self._parse(opcode, body, end, kinds[opcode])
                if opcode == OP_SCHEMA:
                    self.summary_schemas[record.id] = record
                elif opcode == OP_CHANNEL:
                    self.summary_channels[record.id] = record
                else:
                    self.chunk_index[record.chunk_start_offset] = record
            pos = end
        self.summary_start = start

    # -- chunks --------------------------------------------------------------------------
    def _chunk_records(self, body, end):
        """Check and open a chunk; return its records or raise ``_DamagedRecord``."""
        from mcap.records import Chunk
        from mcap.stream_reader import breakup_chunk
        try:
            chunk = self._parse(OP_CHUNK, body, end, Chunk)
            try:
                raw = decompress_chunk(chunk.data, chunk.compression, chunk.uncompressed_size)
            except ChunkRefused as exc:
                raise _DamagedRecord(str(exc)) from None
            chunk = Chunk(compression='', data=raw, message_start_time=chunk.message_start_time,
                          message_end_time=chunk.message_end_time,
                          uncompressed_crc=chunk.uncompressed_crc,
                          uncompressed_size=chunk.uncompressed_size)
            return breakup_chunk(chunk, validate_crc=True)
        except _DamagedRecord:
            raise
        except Exception as exc:
            from mcap.stream_reader import CRCValidationError
            raise _DamagedRecord('its CRC does not match' if isinstance(
                exc, CRCValidationError) else f'cannot be decoded: {type(exc).__name__}') \
                from None

    def _plausible_chunk(self, pos):
        """Whether a chunk starts at ``pos``: consistent lengths and an intact CRC."""
        if pos + 9 + _CHUNK_HEAD.size > self.size or self.data[pos] != OP_CHUNK:
            return False
        length = _U64.unpack_from(self.data, pos + 1)[0]
        t0, t1, raw_size, crc, name_len = _CHUNK_HEAD.unpack_from(self.data, pos + 9)
        if t0 > t1 or name_len > 16 or pos + 9 + length > self.size:
            return False
        at = pos + 9 + _CHUNK_HEAD.size + name_len
        if at + 8 > self.size:
            return False
        records_len = _U64.unpack_from(self.data, at)[0]
        if at + 8 + records_len != pos + 9 + length:
            return False
        try:
            self._chunk_records(pos + 9, pos + 9 + length)
        except _DamagedRecord:
            return False
        return crc != 0 or raw_size == records_len

    def _plausible_definition(self, pos):
        """Whether an intact schema or channel record starts at ``pos`` (strict checks)."""
        from mcap.records import Channel, Schema
        try:
            opcode, body, end = self._frame(pos)
            if end - body > MAX_DEFINITION_BYTES:
                return False
            if opcode == OP_SCHEMA:
                schema = self._parse(opcode, body, end, Schema)
                return bool(_NAME.fullmatch(schema.name)) and schema.encoding in SCHEMA_ENCODINGS
            if opcode == OP_CHANNEL:
                channel = self._parse(opcode, body, end, Channel)
                return bool(_TOPIC.fullmatch(channel.topic)) and \
                    channel.message_encoding in MESSAGE_ENCODINGS
        except Exception:
            pass
        return False

    def _resync(self, start):
        """
        Return the next offset from ``start`` where an intact record begins, or None.

        Intact: a chunk whose structure and CRC hold, or a schema or channel record that
        parses exactly with plausible names (these may sit between chunks).
        """
        known = sorted(p for p in self.chunk_index if p >= start)
        limit = self.summary_start or self.size
        for found in _CANDIDATE.finditer(self.data, start, limit):
            pos = found.start()
            if known and pos > known[0]:
                if self._plausible_chunk(known[0]):
                    return known[0]
                known.pop(0)
            if self.data[pos] == OP_CHUNK:
                if self._plausible_chunk(pos):
                    return pos
            elif self._plausible_definition(pos):
                return pos
        for pos in known:
            if self._plausible_chunk(pos):
                return pos
        return None

    def _message_counts(self, chunk_at, end):
        """Messages per channel of the chunk at ``chunk_at``, from its message indexes."""
        from mcap.records import MessageIndex
        counts = Counter()
        index = self.chunk_index.get(chunk_at)
        try:
            if index is not None:
                for channel_id, offset in index.message_index_offsets.items():
                    opcode, body, stop = self._frame(offset)
                    record = self._parse(opcode, body, stop, MessageIndex)
                    counts[channel_id] += len(record.records)
                return counts
            pos = end  # the message indexes follow their chunk in the data section
            while pos < self.size and self.data[pos] == OP_MESSAGE_INDEX:
                opcode, body, stop = self._frame(pos)
                record = self._parse(opcode, body, stop, MessageIndex)
                counts[record.channel_id] += len(record.records)
                pos = stop
        except Exception:
            return None
        return counts if counts or index is not None else None

    # -- the walk ------------------------------------------------------------------------
    def records(self):
        """Yield the file's records in order, skipping and reporting what is damaged."""
        from mcap.records import Channel, Header, Message, MessageIndex, Metadata, Schema
        kinds = {OP_SCHEMA: Schema, OP_CHANNEL: Channel, OP_MESSAGE: Message}
        # read only to check them: a damaged opcode must not make a chunk pass for these
        checked = {OP_HEADER: Header, OP_MESSAGE_INDEX: MessageIndex, OP_METADATA: Metadata}
        if self.data[:8] != MAGIC:
            yield 'damage', 'is damaged: it does not start with the MCAP magic; reading on'
        pos = 8
        resume = 8          # a resync never goes back before this (already yielded)
        last = 8            # start of the last record taken as intact
        limit = self.summary_start or self.size
        while pos < limit:
            try:
                opcode, body, end = self._frame(pos)
                if opcode in END_LENGTHS:
                    if end - body != END_LENGTHS[opcode]:
                        raise _DamagedRecord(f'record at byte {pos} is not what its type says')
                    return
                if opcode == OP_CHUNK:
                    try:
                        records = self._chunk_records(body, end)
                    except _DamagedRecord as exc:
                        yield 'damaged_chunk', (pos, str(exc), self._message_counts(pos, end))
                        # its length may be damaged too: look for the next intact record
                        found = self._resync(pos + 1)
                        if found is None:
                            return
                        pos = resume = last = found
                        continue
                    for record in records:
                        if isinstance(record, (Schema, Channel, Message)):
                            yield 'record', record
                    resume = end
                elif opcode in kinds:
                    yield 'record', self._parse(opcode, body, end, kinds[opcode])
                    resume = end
                elif opcode in checked:
                    self._parse(opcode, body, end, checked[opcode])
                last = pos
                pos = end
            except Exception as exc:  # framing lost: find the next intact chunk
                why = str(exc) if isinstance(exc, _DamagedRecord) else \
                    f'record at byte {pos} cannot be read ({type(exc).__name__})'
                found = self._resync(max(last + 1, resume))
                if found is None:
                    yield 'damage', f'ends early or is damaged: {why}; read up to there'
                    return
                yield 'damage', f'is damaged: {why}; reading on at the chunk at byte {found}'
                pos = last = resume = found
