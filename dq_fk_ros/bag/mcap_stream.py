"""
MCAP files read record by record: bags rosbags cannot open, such as a recording cut short.

``ros2 bag record`` writes ``metadata.yaml`` and the MCAP summary and footer when it stops;
a recording killed on the robot (power lost, SIGKILL) has neither, and rosbags refuses the
bag. The complete chunks before the cut are intact, and :class:`McapStreamBag` reads them
with Foxglove's ``mcap`` stream reader (chunk CRCs checked), in file order, up to the first
record that is cut or damaged. It offers the part of rosbags' ``Reader`` that
:mod:`dq_fk_ros.bag` uses (``connections``, ``messages``, ``start_time``, ``close``), and says
in :attr:`McapStreamBag.damage` where reading stopped.
"""

from collections import Counter
import os

from rosbags.interfaces import (
    Connection, ConnectionExtRosbag2, MessageDefinition, MessageDefinitionFormat)
from rosbags.rosbag2.metadata import parse_qos


class McapStreamBag:
    """
    The messages of one or more MCAP files, read sequentially (no index, no summary needed).

    Opening scans the files once: channels, message counts, first time and where a file
    ends early. :meth:`messages` reads them again, up to the same place.

    :param paths: MCAP files, read in this order (the splits of one recording).
    """

    def __init__(self, paths):
        """Scan ``paths``; raises ``OSError`` if a file cannot be opened."""
        self.paths = [os.fspath(p) for p in paths]
        self.connections = []
        self._by_channel = {}       # (file index, channel id) -> Connection
        self.damage = None          # one line: where and why reading stopped, or None
        self.note = None            # one line for the user about how the bag is read
        counts = Counter()
        self.start_time = None      # earliest log time (ns), as rosbags' Reader.start_time
        for conn_id, _, log_time in self._records(scanning=True):
            counts[conn_id] += 1
            if self.start_time is None or log_time < self.start_time:
                self.start_time = log_time
        self.start_time = self.start_time or 0
        self.connections = [c._replace(msgcount=counts[c.id]) for c in self.connections]
        self._by_id = {c.id: c for c in self.connections}
        self._by_channel = {key: self._by_id[c.id] for key, c in self._by_channel.items()}

    def close(self):
        """Do nothing: every pass closes its file."""

    def messages(self, connections=None, start=None, stop=None):
        """
        Yield ``(connection, log_time_ns, raw)`` in file order, up to the damage if any.

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
        from mcap.records import Channel, Message, Schema
        from mcap.stream_reader import StreamReader
        for file_index, path in enumerate(self.paths):
            schemas, local = {}, {}
            read = 0
            with open(path, 'rb') as f:
                reader = StreamReader(f, validate_crcs=True,
                                      record_size_limit=max(os.path.getsize(path), 1))
                records = reader.records
                while True:
                    try:
                        record = next(records)
                    except StopIteration:
                        break
                    except Exception as exc:  # cut short or damaged: stop at this record
                        if scanning:  # (the second pass stops at the same record)
                            why = type(exc).__name__ + (f': {exc}' if str(exc) else '')
                            self.damage = '; '.join(filter(None, [
                                self.damage, f'{path} ends early or is damaged after {read} '
                                f'complete records ({why}); read up to there']))
                        break
                    read += 1
                    if isinstance(record, Schema):
                        schemas[record.id] = record
                    elif isinstance(record, Channel):
                        conn = self._connection(file_index, record, schemas) if scanning \
                            else self._by_channel[(file_index, record.id)]
                        local[record.id] = conn.id
                    elif isinstance(record, Message) and record.channel_id in local:
                        yield local[record.channel_id], record.data, record.log_time

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
