"""
Reading joint-state bags: one reader interface (:class:`BagReader`), one adapter per format.

:func:`open_reader` finds a bag's format in :data:`~dq_fk_ros.storage.formats.FORMATS` and
opens it with that format's adapter: a rosbag2 folder (MCAP or sqlite3) with rosbags
(:class:`~dq_fk_ros.storage.rosbag2_reader.Rosbag2Reader`), a bare ``.mcap`` file or a damaged
rosbag2 record by record (:class:`~dq_fk_ros.storage.mcap_stream.McapStreamBag`), a ROS 1
``.bag`` file (:class:`~dq_fk_ros.storage.ros1_bag.Ros1Bag`). A new input format is one adapter
and one row of ``FORMATS``. :func:`joint_state_connections` finds the
``sensor_msgs/JointState`` topic in a reader. Problems with a bag are :class:`BagError`,
whose message is one line.
"""

import os

from dq_fk_ros.errors import BagDamaged, BagError
from dq_fk_ros.storage.formats import bag_format, BagFormat, FORMATS
from dq_fk_ros.storage.reader_interface import (
    BagReader, check_bag_files, JOINT_STATE, mcap_folder_files)
from dq_fk_ros.storage.text import printable

__all__ = ['BagFormat', 'BagReader', 'FORMATS', 'JOINT_STATE', 'bag_format',
           'joint_state_connections', 'mcap_folder_files', 'open_reader']


def open_reader(path, reference=False, ros1_type=JOINT_STATE) -> BagReader:
    """
    Open a bag for reading with its format's adapter (:data:`FORMATS`).

    An intact rosbag2 MCAP folder is read a chunk at a time
    (:class:`~dq_fk_ros.storage.mcap_chunks.McapChunkReader`); ``reference``: with rosbags'
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
    return (fmt.reference if reference and fmt.reference else fmt.opener)(path, ros1_type)


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
