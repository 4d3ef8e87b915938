"""
Reading joint-state bags: one reader interface (:class:`BagReader`), one adapter per format.

:func:`open_reader` finds a bag's format in :data:`FORMATS` and opens it with that format's
adapter: a rosbag2 folder (MCAP or sqlite3) with rosbags
(:class:`~dq_fk_ros.bag.rosbag2_reader.Rosbag2Reader`), a bare ``.mcap`` file or a damaged
rosbag2 record by record (:class:`~dq_fk_ros.bag.mcap_stream.McapStreamBag`), a ROS 1
``.bag`` file (:class:`~dq_fk_ros.bag.ros1_bag.Ros1Bag`). A new input format is one adapter
and one row of :data:`FORMATS`. :func:`joint_state_connections` finds the
``sensor_msgs/JointState`` topic in a reader. Problems with a bag are :class:`BagError`,
whose message is one line.
"""

from dataclasses import dataclass
import os
from typing import Callable, Optional

from dq_fk_ros.bag.reader_interface import (
    BagReader, check_bag_files, JOINT_STATE, mcap_folder_files)
from dq_fk_ros.bag.text import printable
from dq_fk_ros.errors import BagDamaged, BagError

__all__ = ['BagFormat', 'BagReader', 'FORMATS', 'JOINT_STATE', 'bag_format',
           'joint_state_connections', 'mcap_folder_files', 'open_reader']


@dataclass(frozen=True)
class BagFormat:
    """
    One input format: its name, whether a path is one, and its adapter's opener.

    ``reference``: the opener of the reference reader of the format, where it has a faster
    one (None: ``opener`` is the reference).
    """

    name: str
    what: str
    matches: Callable[[str], bool]
    opener: Callable[[str], BagReader]
    reference: Optional[Callable[[str], BagReader]] = None


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


def _open_mcap_file(path: str) -> BagReader:
    from dq_fk_ros.bag.mcap_stream import open_stream_bag
    return open_stream_bag([path], path, None)


def _open_ros1(path: str, msgtype: str = JOINT_STATE) -> BagReader:
    from dq_fk_ros.bag.ros1_bag import Ros1Bag
    return Ros1Bag(path, msgtype=msgtype)


def _open_rosbag2(path: str) -> BagReader:
    from dq_fk_ros.bag.rosbag2_reader import open_rosbag2
    return open_rosbag2(path)


def _open_rosbag2_reference(path: str) -> BagReader:
    from dq_fk_ros.bag.rosbag2_reader import open_rosbag2
    return open_rosbag2(path, reference=True)


FORMATS = (
    BagFormat('mcap', 'a bare .mcap file', _is_mcap_file, _open_mcap_file),
    BagFormat('ros1', 'a ROS 1 .bag file', _is_ros1_file, _open_ros1),
    BagFormat('rosbag2', 'a rosbag2 folder (MCAP or sqlite3)', lambda path: True,
              _open_rosbag2, _open_rosbag2_reference),
)


def bag_format(path) -> BagFormat:
    """Return the first format of :data:`FORMATS` that ``path`` is (rosbag2 the last)."""
    path = os.fspath(path)
    return next(f for f in FORMATS if f.matches(path))


def open_reader(path, reference=False, ros1_type=JOINT_STATE) -> BagReader:
    """
    Open a bag for reading with its format's adapter (:data:`FORMATS`).

    An intact rosbag2 MCAP folder is read a chunk at a time
    (:class:`~dq_fk_ros.bag.mcap_chunks.McapChunkReader`); ``reference``: with rosbags'
    reader instead, the reference it is held equal to.

    A rosbag2 folder rosbags cannot open (no ``metadata.yaml``, no MCAP summary: a
    recording that did not stop cleanly), one whose MCAP summary fails its CRC, and a bare
    ``.mcap`` file are read record by record, skipping damaged chunks; the reader's ``note``
    says so and its ``damage`` what was skipped. A ROS 1 ``.bag`` file is read with rosbags
    and its JointStates (or the messages of ``ros1_type``) converted to ROS 2 CDR. A bag
    that is or holds a FIFO or device
    is refused before anything is opened (:func:`check_bag_files`). Raises :class:`BagError`.
    """
    path = os.fspath(path)
    if not os.path.lexists(path):
        raise BagError(f'{path}: no such bag')
    check_bag_files(path)
    fmt = bag_format(path)
    if fmt.name == 'ros1':
        return _open_ros1(path, ros1_type)
    return (fmt.reference if reference and fmt.reference else fmt.opener)(path)


def joint_state_connections(reader: BagReader, path, topic=None) -> list:
    """
    Return the connections of the JointState topic (``topic``, or the only one).

    Raises :class:`BagError`, or :class:`BagDamaged` when the topic is missing from a bag
    whose damage may have taken its definition.
    """
    try:
        return _joint_state_connections(reader, path, topic)
    except BagError as exc:
        if reader.damage:
            raise BagDamaged(f'{exc}; {reader.damage}') from None
        raise


def _joint_state_connections(reader, path, topic):
    topics = reader.all_topics
    listing = ', '.join(f'{printable(t)} ({printable(m)})' for t, m in topics[:20]) + \
        (f' and {len(topics) - 20} more' if len(topics) > 20 else '') or 'none'
    if topic is not None:
        conns = [c for c in reader.connections if c.topic == topic]
        if not conns:
            raise BagError(f'{path} has no topic {topic!r}; its topics: {listing}')
        wrong = [c.msgtype for c in conns if c.msgtype != JOINT_STATE]
        if wrong:
            raise BagError(f'{path}: topic {topic!r} has type {printable(wrong[0])}, '
                           f'not {JOINT_STATE}')
        return conns
    conns = [c for c in reader.connections if c.msgtype == JOINT_STATE]
    topics = sorted({c.topic for c in conns})
    if not topics:
        raise BagError(f'{path} has no {JOINT_STATE} topic; its topics: {listing}')
    if len(topics) > 1:
        raise BagError(f'{path} has several JointState topics '
                       f'({", ".join(printable(t) for t in topics[:20])}); pick one with --topic')
    return conns
