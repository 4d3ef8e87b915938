"""
A rosbag2 MCAP bag written without rosbags' modules: ``dq_fk_bag process``'s output.

:class:`McapBagWriter` is rosbags' ``Writer`` (version 9, MCAP storage, the surface
``dq_fk_bag`` uses: ``open``, ``add_connection``, ``write``, ``close``, ``abort``) with
:class:`~dq_fk_ros.storage.mcap_writer.ArrayWrites` (arrays of messages) over
:class:`~dq_fk_ros.storage.mcap_writer.McapChunkStorage`, its ``metadata.yaml`` from
:mod:`~dq_fk_ros.storage.rosbag2_metadata`. Importing ``rosbags.rosbag2`` costs ~40 ms of every
command and its YAML dumps ~15 ms; the reference is
:class:`~dq_fk_ros.storage.rosbags_writer.RosbagsWriter` (rosbags' ``Writer`` over the same
storage): test_bag_writer.py holds the two bags equal
byte for byte.
"""

import os
from pathlib import Path

from dq_fk_ros.errors import BagError
from dq_fk_ros.storage.mcap_writer import ArrayWrites, COMPRESSIONS, McapChunkStorage
from dq_fk_ros.storage.rosbag2_metadata import dump_qos, information, to_yaml
from rosbags.interfaces import (
    Connection, ConnectionExtRosbag2, MessageDefinition, MessageDefinitionFormat)


class McapBagWriter(ArrayWrites):
    """
    A version 9 rosbag2 folder of one MCAP file, as rosbags' ``Writer`` writes it.

    Its misuses (not opened, an unknown connection) raise :class:`BagError`.

    :param path: the bag folder to create (it must not exist).
    :param compression: MCAP chunks ``'none'``, ``'zstd'`` or ``'lz4'`` (as rosbag2's MCAP
        storage compresses: chunk by chunk, ``metadata.yaml`` naming no compression).
    """

    error = BagError

    def __init__(self, path, compression='none'):
        """Prepare the bag; :meth:`open` creates it. Raises :class:`BagError`."""
        if compression not in COMPRESSIONS:
            raise BagError(f'compression {compression!r}: one of {", ".join(COMPRESSIONS)}')
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f'{self.path} exists already, not overwriting.')
        self.compression = compression
        self.storage = None
        self.connections = []
        self.counts = {}
        self.added_types = set()
        self._qos_texts = {}   # QoS profiles -> their YAML text
        self.min_timestamp, self.max_timestamp = 2 ** 63 - 1, 0

    def open(self) -> None:  # noqa: A003 (rosbags' Writer.open)
        """Create the folder and its MCAP file (header written)."""
        try:
            self.path.mkdir(mode=0o755, parents=True)
        except FileExistsError:
            raise BagError(f'{self.path} exists already, not overwriting.') from None
        self.storage = McapChunkStorage(self.path, None, self.compression)

    def add_connection(self, topic, msgtype, *, typestore=None, msgdef=None, rihs01=None,
                       serialization_format='cdr', offered_qos_profiles=()) -> Connection:
        """
        Add a topic and return its connection (rosbags' ``Writer.add_connection``).

        :param msgdef: the type's definition (``ros2msg``, or ``ros2idl`` text), with
            ``rihs01`` its hash; else both from ``typestore``.
        """
        if self.storage is None:
            raise BagError('Bag was not opened.')
        if msgdef is None or rihs01 is None:
            if typestore is None:
                raise BagError('Cannot determine message definition. Use either the '
                               'typestore or msgdef+rihs01 arguments.')
            msgdef = typestore.generate_msgdef(msgtype, ros_version=2)[0]
            rihs01 = typestore.hash_rihs01(msgtype)
        idl = msgdef.startswith('=' * 80 + '\nIDL: ')
        connection = Connection(
            id=len(self.connections) + 1, topic=topic, msgtype=msgtype,
            msgdef=MessageDefinition(
                MessageDefinitionFormat.IDL if idl else MessageDefinitionFormat.MSG, msgdef),
            digest=rihs01, msgcount=0,
            ext=ConnectionExtRosbag2(serialization_format=serialization_format,
                                     offered_qos_profiles=list(offered_qos_profiles)),
            owner=self)
        if any((c.topic, c.msgtype, c.ext) == (topic, msgtype, connection.ext)
               for c in self.connections):
            raise BagError(f'Connection can only be added once: {connection!r}.')
        if msgtype not in self.added_types:
            self.storage.add_msgtype(connection)
            self.added_types.add(msgtype)
        qos = tuple(offered_qos_profiles)   # (the topics share a few: each dumped once)
        if qos not in self._qos_texts:
            self._qos_texts[qos] = to_yaml(dump_qos(qos)).strip()
        self.storage.add_connection(connection, self._qos_texts[qos])
        self.connections.append(connection)
        self.counts[connection.id] = 0
        return connection

    def write(self, connection, timestamp, data) -> None:
        """Write one serialized message (log time ``timestamp`` ns)."""
        if self.storage is None:
            raise BagError('Bag was not opened.')
        if connection not in self.connections:
            raise BagError(f'Tried to write to unknown connection {connection!r}.')
        self.storage.write(connection, timestamp, data)
        self.counts[connection.id] += 1
        self.min_timestamp = min(timestamp, self.min_timestamp)
        self.max_timestamp = max(timestamp, self.max_timestamp)

    def close(self) -> None:
        """Finish the MCAP file (summary, footer) and write ``metadata.yaml``."""
        storage, self.storage = self.storage, None
        if storage is None:
            raise BagError('Bag was not opened.')
        info = information(self.connections, self.counts, self.min_timestamp,
                           self.max_timestamp, storage.path.name)
        storage.close(9, to_yaml(info).strip())
        metadata = self.path / 'metadata.yaml'
        part = self.path / 'metadata.yaml.tmp'
        part.write_text(to_yaml({'rosbag2_bagfile_information': info}), 'utf8')
        os.replace(part, metadata)


__all__ = ['McapBagWriter']
