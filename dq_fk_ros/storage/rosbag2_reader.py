"""
A rosbag2 folder (MCAP or sqlite3) read with rosbags: the reference reader.

:func:`open_rosbag2` opens it as a :class:`~dq_fk_ros.storage.reader_interface.BagReader`. An
intact MCAP folder is read a chunk at a time
(:class:`~dq_fk_ros.storage.mcap_chunks.McapChunkReader`)
unless the reference is asked for, opened without rosbags where
:func:`~dq_fk_ros.storage.mcap_folder.open_mcap_folder` takes it; a folder rosbags cannot open,
or whose MCAP summary fails its CRC, is read record by record instead
(:class:`~dq_fk_ros.storage.mcap_stream.McapStreamBag`), with a note saying so.
"""

import os
from typing import Iterator, Optional

from dq_fk_ros.errors import BagError
from dq_fk_ros.storage.mcap_stream import open_stream_bag
from dq_fk_ros.storage.mcap_summary import summary_intact
from dq_fk_ros.storage.reader_interface import BagReader, BatchesFromMessages, mcap_folder_files
from dq_fk_ros.storage.text import one_line


def open_rosbag2(path: str, reference: bool = False) -> BagReader:
    """
    Open a rosbag2 folder with rosbags, or record by record where rosbags cannot.

    :param reference: read an intact MCAP folder with rosbags' reader itself (else a chunk
        at a time, :class:`~dq_fk_ros.storage.mcap_chunks.McapChunkReader`, in rosbags' order).
    """
    info = _information(path)   # (its bounds checked before rosbags makes a connection
    if not reference and info is not None:   # of every topic)
        from dq_fk_ros.storage.mcap_folder import open_mcap_folder
        fast = open_mcap_folder(path, info)
        if fast is not None:
            return fast
    from dq_fk_ros.storage.decompress import bound_rosbags
    bound_rosbags()
    from rosbags.rosbag2 import Reader
    try:
        reader = Reader(path)
        reader.open()
    except Exception as exc:  # rosbags cannot open it (ReaderError, or damage it trips on)
        mcaps = mcap_folder_files(path)
        if not mcaps:
            hint = ' (a ROS 1 bag is a single .bag file)' if os.path.isdir(path) else ''
            raise BagError(f'{path}: not a readable rosbag2{hint} ({one_line(exc)})') \
                from None
        if not os.path.exists(os.path.join(path, 'metadata.yaml')):
            exc = 'no metadata.yaml'
        return open_stream_bag(mcaps, path, one_line(exc))
    mcaps = mcap_folder_files(path)
    damaged = [f for f in mcaps if not _summary_intact(f)]
    if damaged:
        reader.close()
        return open_stream_bag(mcaps, path, f'the summary of {os.path.basename(damaged[0])} '
                                            f'fails its CRC')
    rosbags = Rosbag2Reader(reader, path, mcaps)
    files = None if reference else _chunked_files(reader)
    if not files:
        return rosbags
    from dq_fk_ros.storage.mcap_chunks import ChunkDamaged, McapChunkReader
    try:
        return McapChunkReader(rosbags, files)
    except (ChunkDamaged, OSError, ValueError):  # left to rosbags, which says what it finds
        return open_rosbag2(path, reference=True)


def _information(path):
    """
    Return the folder's metadata (``read_information``), or None where rosbags reads it.

    Raises BagError for a ``metadata.yaml`` larger than rosbag2 writes.
    """
    from dq_fk_ros.storage.rosbag2_metadata import NotTaken, read_information
    try:
        return read_information(path)
    except NotTaken:   # (none, not YAML...): rosbags says what it finds
        return None


def _chunked_files(reader):
    """Return the MCAP files rosbags reads, in its order, if chunks may be read whole."""
    storages = getattr(getattr(reader, 'storage', None), 'storages', None)
    if not storages or reader.compression_mode in ('message', 'file'):
        return None  # per-message or whole-file compression: rosbags' own path
    paths = [getattr(s, 'path', None) for s in storages]
    if not all(p is not None and str(p).endswith('.mcap') for p in paths):
        return None
    return [str(p) for p in paths]


def _summary_intact(path):
    """Whether an MCAP file's summary passes its CRC (a file without one passes)."""
    try:
        return summary_intact(path)
    except OSError:
        return False


class Rosbag2Reader(BatchesFromMessages):
    """
    rosbags' ``Reader`` of an intact rosbag2 folder, as a ``BagReader``.

    Its ``fallback`` reads the same MCAP files record by record, for when rosbags stops
    inside a damaged chunk (a sqlite3 bag has none).
    """

    note = None
    damage = None
    copies_messages = True
    windowable = True

    def __init__(self, reader, path: str, mcaps: list):
        """Adopt an open rosbags ``Reader`` of ``path``, whose MCAP files are ``mcaps``."""
        self._reader, self._path, self._mcaps = reader, path, mcaps
        self.connections = list(reader.connections)
        self.all_topics = [(c.topic, c.msgtype) for c in self.connections]
        self.start_time, self.end_time = reader.start_time, reader.end_time

    def messages(self, connections=None, start=None, stop=None) -> Iterator[tuple]:
        """Yield ``(connection, log_time_ns, raw CDR bytes)`` in log-time order."""
        conns = self.connections if connections is None else connections
        return self._reader.messages(connections=conns, start=start, stop=stop)

    def fallback(self) -> Optional[BagReader]:
        """Return the record-by-record reader of the same MCAP files (None for sqlite3)."""
        return open_stream_bag(self._mcaps, self._path, 'a damaged chunk') \
            if self._mcaps else None

    def close(self) -> None:
        """Close rosbags' reader."""
        self._reader.close()
