"""
rosbag2 bags written through rosbags' ``Writer``: sqlite3 output, and the MCAP reference.

rosbags' :class:`~rosbags.rosbag2.Writer` does its part (connections, QoS profiles, message
definitions and type hashes, ``metadata.yaml``, version 9); what it cannot do fast is one
Python call per message: ``dq_fk_bag process`` writes eight messages per joint state.
:class:`RosbagsWriter` adds ``write_rows`` and ``write_templates`` (arrays of messages,
:class:`~dq_fk_ros.storage.mcap_writer.ArrayWrites`) on two storages that take them:
:class:`~dq_fk_ros.storage.mcap_writer.McapChunkStorage` (MCAP) and :class:`Sqlite3BulkStorage`
(rosbags' sqlite3 storage with ``executemany``).

``dq_fk_bag process`` writes sqlite3 bags with it, MCAP bags with
:class:`~dq_fk_ros.storage.mcap_bag_writer.McapBagWriter` (the same storage, without importing
rosbags' rosbag2 modules); test_bag_writer.py holds the two MCAP bags equal byte for byte.
"""

from functools import partial

from dq_fk_ros.storage.mcap_writer import ArrayWrites, COMPRESSIONS, McapChunkStorage
from rosbags.rosbag2 import CompressionMode, StoragePlugin, Writer, WriterError
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Writer


class Sqlite3BulkStorage(Sqlite3Writer):
    """rosbags' sqlite3 storage, plus :meth:`write_rows` with one ``executemany``."""

    def write_rows(self, channel_ids, log_times_ns, payloads) -> None:
        """Insert message i of every channel for every i, in that order."""
        times = [int(t) for t in log_times_ns]
        rows = ((cid, t, payload[i].tobytes()) for i, t in enumerate(times)
                for cid, payload in zip(channel_ids, payloads))
        self.cursor.executemany(
            'INSERT INTO messages (topic_id, timestamp, data) VALUES(?, ?, ?)', rows)

    def write_templates(self, channel_ids, log_times_ns, stamps_ns, templates, values) -> None:
        """:meth:`write_rows` of ``template.fill(stamps_ns, value)`` per channel."""
        self.write_rows(channel_ids, log_times_ns,
                        [t.fill(stamps_ns, v) for t, v in zip(templates, values)])


class RosbagsWriter(ArrayWrites, Writer):
    """
    rosbags' rosbag2 ``Writer`` (version 9) with arrays of messages (:class:`ArrayWrites`).

    :param path: the bag folder to create.
    :param storage: ``'mcap'`` or ``'sqlite3'``.
    :param compression: MCAP chunks ``'none'``, ``'zstd'`` or ``'lz4'`` (as rosbag2's MCAP
        storage compresses: chunk by chunk, ``metadata.yaml`` naming no compression).
    """

    error = WriterError
    STORAGE_PLUGINS = {StoragePlugin.MCAP: McapChunkStorage,
                       StoragePlugin.SQLITE3: Sqlite3BulkStorage}

    def __init__(self, path, storage='mcap', compression='none'):
        """Prepare a version 9 bag of the given storage; :meth:`open` creates it."""
        plugins = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}
        if compression not in COMPRESSIONS:
            raise WriterError(f'compression {compression!r}: one of {", ".join(COMPRESSIONS)}')
        if compression != 'none' and storage != 'mcap':
            raise WriterError(f'{storage} bags are written uncompressed; compression is for '
                              f'MCAP chunks')
        super().__init__(path, version=9, storage_plugin=plugins[storage])
        if compression != 'none':
            self.STORAGE_PLUGINS = dict(self.STORAGE_PLUGINS)
            self.STORAGE_PLUGINS[StoragePlugin.MCAP] = partial(
                McapChunkStorage, chunk_compression=compression)
            self.compression_mode = CompressionMode.STORAGE
