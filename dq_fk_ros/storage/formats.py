"""
The bag formats, one row each (:data:`FORMATS`): what a bag of it is, its reader, its writers.

A row says which paths are a bag of its format (``found``: what a fleet's walk takes for
one; ``matches``: what :func:`~dq_fk_ros.storage.reading.open_reader` reads with it), its
adapter's opener (a :class:`~dq_fk_ros.storage.reader_interface.BagReader`) and its reference
where it has a faster one, the writers of the storages it writes (each a
:class:`~dq_fk_ros.storage.writer_interface.BagWriter`), and where a bag of it may be cut for
the fleet's workers (``chunk_counts``; None: never cut). A new format is one adapter module
and one row here (docs/architecture.md, "Where a change goes").
"""

from dataclasses import dataclass, field
import os
from typing import Callable, Mapping, Optional

from dq_fk_ros.errors import BagError
from dq_fk_ros.storage.mcap_indexes import ChunkCounts, mcap_chunk_counts
from dq_fk_ros.storage.reader_interface import BagReader, JOINT_STATE, mcap_folder_files
from dq_fk_ros.storage.writer_interface import BagWriter


@dataclass(frozen=True)
class BagFormat:
    """
    One bag format.

    :param name: its name (``--storage`` takes the keys of ``writers``).
    :param what: what a user calls it, for messages.
    :param found: ``found(path)``: whether a fleet's walk takes the file or folder for a bag
        of this format.
    :param matches: ``matches(path)``: whether :func:`~dq_fk_ros.storage.reading.open_reader`
        reads ``path`` as this format (the first row that matches).
    :param opener: ``opener(path, msgtype)``: its reader (``msgtype``: what a ROS 1 bag's
        messages are converted from; the other formats keep every type).
    :param reference: the opener of the reference reader, where ``opener`` is a faster one.
    :param writers: storage name -> ``writer(path, compression)``, a new bag not yet open.
    :param chunk_counts: ``chunk_counts(path, topic)``: where a bag may be cut, or None.
    :param suffix: a file bag's extension (its output folder drops it).
    """

    name: str
    what: str
    found: Callable[[str], bool]
    matches: Callable[[str], bool]
    opener: Callable[..., BagReader]
    reference: Optional[Callable[..., BagReader]] = None
    writers: Mapping[str, Callable[[str, str], BagWriter]] = field(default_factory=dict)
    chunk_counts: Optional[Callable[[str, str], Optional[ChunkCounts]]] = None
    suffix: str = ''


def _is_named(suffix):
    return lambda path: path.endswith(suffix)


def _is_mcap_file(path: str) -> bool:
    return os.path.isfile(path) and path.endswith('.mcap')


def _is_ros1_file(path: str) -> bool:
    if not os.path.isfile(path):
        return False
    try:
        with open(path, 'rb') as f:
            return f.read(13) == b'#ROSBAG V2.0\n'
    except OSError as exc:  # a file that cannot be read (a device, /proc): say which
        raise BagError(f'{path}: cannot be read ({exc.strerror or exc})') from None


def _is_rosbag2_folder(path: str) -> bool:
    """Say whether ``path`` is a rosbag2 folder (metadata.yaml, or storage files in it)."""
    try:
        names = os.listdir(path)
    except OSError:
        return False
    return 'metadata.yaml' in names or any(
        n.endswith(('.mcap', '.db3')) and os.path.isfile(os.path.join(path, n))
        for n in names)


def _open_mcap_file(path: str, msgtype: str = JOINT_STATE) -> BagReader:
    from dq_fk_ros.storage.mcap_stream import open_stream_bag
    return open_stream_bag([path], path, None)


def _open_ros1(path: str, msgtype: str = JOINT_STATE) -> BagReader:
    from dq_fk_ros.storage.ros1_bag import Ros1Bag
    return Ros1Bag(path, msgtype=msgtype)


def _open_rosbag2(path: str, msgtype: str = JOINT_STATE) -> BagReader:
    from dq_fk_ros.storage.rosbag2_reader import open_rosbag2
    return open_rosbag2(path)


def _open_rosbag2_reference(path: str, msgtype: str = JOINT_STATE) -> BagReader:
    from dq_fk_ros.storage.rosbag2_reader import open_rosbag2
    return open_rosbag2(path, reference=True)


def _mcap_writer(path: str, compression: str) -> BagWriter:
    from dq_fk_ros.storage.mcap_bag_writer import McapBagWriter
    return McapBagWriter(path, compression)


def _sqlite3_writer(path: str, compression: str) -> BagWriter:
    from dq_fk_ros.storage.rosbags_writer import RosbagsWriter
    return RosbagsWriter(path, 'sqlite3', compression)


def _mcap_counts(path: str, topic: str) -> Optional[ChunkCounts]:
    files = [path] if os.path.isfile(path) else mcap_folder_files(path)
    return mcap_chunk_counts(files, topic) if files else None


FORMATS = (
    BagFormat('mcap', 'a bare .mcap file', _is_named('.mcap'), _is_mcap_file, _open_mcap_file,
              chunk_counts=_mcap_counts, suffix='.mcap'),
    BagFormat('ros1', 'a ROS 1 .bag file', _is_named('.bag'), _is_ros1_file, _open_ros1,
              suffix='.bag'),
    BagFormat('rosbag2', 'a rosbag2 folder (MCAP or sqlite3)', _is_rosbag2_folder,
              lambda path: True, _open_rosbag2, _open_rosbag2_reference,
              {'mcap': _mcap_writer, 'sqlite3': _sqlite3_writer}, _mcap_counts),
)
STORAGES = tuple(name for f in FORMATS for name in f.writers)


def bag_format(path) -> BagFormat:
    """
    Return the first format of :data:`FORMATS` that ``path`` matches (rosbag2 the last).

    rosbag2 is the catch-all: its reader says what is missing (a folder without
    ``metadata.yaml``, a file that is no bag).
    """
    path = os.fspath(path)
    return next(f for f in FORMATS if f.matches(path))


def is_bag_folder(path) -> bool:
    """Say whether the folder ``path`` is a bag of a folder format (a rosbag2 folder)."""
    return os.path.isdir(path) and any(f.found(path) for f in FORMATS if not f.suffix)


def is_bag_file(path) -> bool:
    """Say whether the file ``path``, met in a fleet's walk, is a bag of a file format."""
    return any(f.found(path) for f in FORMATS if f.suffix)


def strip_suffix(name) -> str:
    """Return a bag file's name without its format's extension (its output folder's name)."""
    # (.db3: a rosbag2 sqlite3 file named alone)
    for suffix in [f.suffix for f in FORMATS if f.suffix] + ['.db3']:
        if name.endswith(suffix):
            return name[:-len(suffix)]
    return name


def open_bag_writer(path, storage: str = 'mcap', compression: str = 'none') -> BagWriter:
    """
    Return an open writer of the new bag ``path`` in ``storage`` (one of :data:`STORAGES`).

    MCAP is written by :class:`~dq_fk_ros.storage.mcap_bag_writer.McapBagWriter`, sqlite3
    through rosbags (:class:`~dq_fk_ros.storage.rosbags_writer.RosbagsWriter`).
    """
    make = next((f.writers[storage] for f in FORMATS if storage in f.writers), None)
    if make is None:
        storages = ', '.join(name for f in FORMATS for name in f.writers)
        raise BagError(f'--storage {storage!r}: one of {storages}')
    writer = make(path, compression)
    writer.open()
    return writer


__all__ = ['bag_format', 'BagFormat', 'FORMATS', 'is_bag_file', 'is_bag_folder',
           'open_bag_writer', 'STORAGES', 'strip_suffix']
