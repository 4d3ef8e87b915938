"""
A rosbag2 folder of intact MCAP files opened without rosbags: ``dq_fk_bag process``'s start.

:func:`open_mcap_folder` reads ``metadata.yaml`` (:mod:`~dq_fk_ros.storage.rosbag2_metadata`) and
every file's summary (:mod:`~dq_fk_ros.storage.mcap_summary`) and returns a
:class:`~dq_fk_ros.storage.mcap_chunks.McapChunkReader` whose connections, times and fallback
come from :class:`McapFolder`: what rosbags' ``Reader`` would give (test_rosbag2_metadata.py
holds them equal), without importing ``rosbags.rosbag2`` (~40 ms). A folder it does not take
(another storage or version, compression of files or messages, anything damaged or unusual)
gives None, and :func:`~dq_fk_ros.storage.rosbag2_reader.open_rosbag2` opens it with rosbags as
before: every damaged-input case goes the way it went.
"""

from typing import Optional

from dq_fk_ros.errors import BagError
from dq_fk_ros.storage.mcap_stream import open_stream_bag
from dq_fk_ros.storage.mcap_summary import read_summary, SummaryRefused, SummaryTooLarge
from dq_fk_ros.storage.reader_interface import BagReader, mcap_folder_files
from dq_fk_ros.storage.rosbag2_metadata import (
    mcap_folder, NotTaken, parse_qos, read_information, with_definitions)


class McapFolder:
    """
    The connections, times and fallback of a rosbag2 MCAP folder (as rosbags' ``Reader``).

    The ``reference`` a :class:`~dq_fk_ros.storage.mcap_chunks.McapChunkReader` takes them from;
    it holds no file open.
    """

    def __init__(self, path, connections, start_time, end_time):
        """Keep what :func:`open_mcap_folder` read."""
        self._path = path
        self.connections = connections
        self.all_topics = [(c.topic, c.msgtype) for c in connections]
        self.start_time, self.end_time = start_time, end_time

    def fallback(self) -> Optional[BagReader]:
        """Return the record-by-record reader of the folder's MCAP files (damage skipped)."""
        return open_stream_bag(mcap_folder_files(self._path), self._path, 'a damaged chunk')

    def close(self) -> None:
        """Nothing to release (the chunk reader holds the files)."""


def _definitions(summary):
    """Return the ``(msgtype, encoding, text)`` of a file's channels with a schema."""
    try:
        texts = {k: s.data.decode('utf-8') for k, s in summary.schemas.items()}
    except UnicodeDecodeError:   # rosbags decodes every schema, and fails on this one
        raise NotTaken('a schema that is not UTF-8') from None
    return [(summary.schemas[c.schema_id].name, summary.schemas[c.schema_id].encoding,
             texts[c.schema_id]) for c in summary.channels.values()
            if c.schema_id in summary.schemas]


def open_mcap_folder(path: str, info: Optional[dict] = None) -> Optional[BagReader]:
    """
    Return a chunk reader of the rosbag2 MCAP folder ``path``, or None (left to rosbags).

    :param info: its metadata, already read
        (:func:`~dq_fk_ros.storage.rosbag2_metadata.read_information`; None: read here).

    None also where a file cannot be read: rosbags then says what is wrong. Raises
    :class:`~dq_fk_ros.errors.BagError` for a ``metadata.yaml`` larger than rosbag2 writes
    (:func:`~dq_fk_ros.storage.rosbag2_metadata.check_bounds`) and for a summary listing more
    than :data:`~dq_fk_ros.storage.mcap_summary.MAX_CHANNELS` channels.
    """
    from dq_fk_ros.storage.mcap_chunks import ChunkDamaged, McapChunkReader
    try:
        info = read_information(path) if info is None else info
        files, connections, start, end = mcap_folder(path, info)
        summaries = []
        for f in files:
            try:
                summaries.append(read_summary(f, qos=parse_qos))
            except SummaryTooLarge as exc:   # (each channel's QoS text parsed: time bound)
                raise BagError(f'{f}: {exc}') from None
        connections = with_definitions(connections, [_definitions(s) for s in summaries])
        return McapChunkReader(McapFolder(path, connections, start, end), files, summaries)
    except (NotTaken, SummaryRefused, ChunkDamaged, OSError, ValueError):
        return None


__all__ = ['McapFolder', 'open_mcap_folder']
