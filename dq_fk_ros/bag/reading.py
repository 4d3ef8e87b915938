"""
Reading joint-state bags: rosbags' ``Reader``, or a damaged recording record by record.

:func:`open_reader` opens a rosbag2 folder (MCAP or sqlite3), a bare ``.mcap`` file or a
ROS 1 ``.bag`` file; :func:`joint_state_connections` finds the ``sensor_msgs/JointState``
topic in it. Problems with a bag are :class:`BagError`, whose message is one line.
"""

import os
import re
import struct

from dq_fk_ros.bag.text import one_line, printable
from dq_fk_ros.errors import BagDamaged, BagError

JOINT_STATE = 'sensor_msgs/msg/JointState'


def open_reader(path):
    """
    Open a bag for reading: rosbags' ``Reader``, or its MCAP files record by record.

    A rosbag2 folder rosbags cannot open (no ``metadata.yaml``, no MCAP summary: a
    recording that did not stop cleanly), one whose MCAP summary fails its CRC, and a bare
    ``.mcap`` file are read with :class:`~dq_fk_ros.bag.mcap_stream.McapStreamBag`, which
    skips damaged chunks; its ``note`` says so and its ``damage`` what was skipped. A ROS 1
    ``.bag`` file is read with rosbags and its JointStates converted to ROS 2 CDR.
    Every reader has ``fallback()``: the record-by-record reader of the same MCAP files
    (None where there is none), for when rosbags stops inside a damaged chunk.
    Raises :class:`BagError`.
    """
    from dq_fk_ros.bag.decompress import bound_rosbags
    from rosbags.rosbag2 import Reader
    bound_rosbags()
    path = os.fspath(path)
    if not os.path.lexists(path):
        raise BagError(f'{path}: no such bag')
    if os.path.isfile(path) and path.endswith('.mcap'):
        return _stream_bag([path], path, None)
    if os.path.isfile(path) and _is_ros1_bag(path):
        return Ros1Bag(path)
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
        return _stream_bag(mcaps, path, one_line(exc))
    mcaps = mcap_folder_files(path)
    damaged = [f for f in mcaps if not _summary_intact(f)]
    if damaged:
        reader.close()
        return _stream_bag(mcaps, path, f'the summary of {os.path.basename(damaged[0])} '
                                        f'fails its CRC')
    reader.note = reader.damage = None
    reader.fallback = (lambda: _stream_bag(mcaps, path, 'a damaged chunk')) if mcaps \
        else (lambda: None)
    return reader


def _summary_intact(path):
    """Whether an MCAP file's summary passes its CRC (a file without one passes)."""
    from dq_fk_ros.bag.mcap_stream import summary_intact
    try:
        return summary_intact(path)
    except OSError:
        return False


def _is_ros1_bag(path):
    with open(path, 'rb') as f:
        return f.read(13) == b'#ROSBAG V2.0\n'


def mcap_folder_files(folder):
    """List the MCAP files of a bag folder, splits in order (``x_2`` before ``x_10``)."""
    if not os.path.isdir(folder):
        return []
    names = [n for n in os.listdir(folder) if n.endswith('.mcap')]
    split = re.compile(r'^(.*?)(\d*)\.mcap$')
    return [os.path.join(folder, n) for n in sorted(
        names, key=lambda n: (split.match(n)[1], int(split.match(n)[2] or -1)))]


def _stream_bag(files, path, why):
    from dq_fk_ros.bag.mcap_stream import McapStreamBag
    try:
        bag = McapStreamBag(files)
    except OSError as exc:
        raise BagError(f'{path}: cannot be read ({exc})') from None
    listing = ', '.join(os.path.basename(f) for f in files)
    bag.note = None if why is None else \
        f'{path}: not a complete rosbag2 ({why}); read {listing} record by record'
    bag.fallback = lambda: None
    return bag


class Ros1Bag:
    """
    A ROS 1 bag, with its JointState messages converted to ROS 2 CDR as they are read.

    Offers what :func:`open_reader`'s readers offer (``connections``, ``messages``,
    ``start_time``, ``close``, ``note``, ``damage``). Only JointState topics are offered:
    other ROS 1 types would need a conversion of their own (``rosbags-convert``, installed
    with rosbags, converts a whole ROS 1 bag to rosbag2).
    """

    def __init__(self, path, scan=False):
        """
        Open the bag; raises :class:`BagError` if it cannot be read at all.

        Through its index with rosbags; if that fails (a damaged, cut-off or misplaced
        index), or with ``scan``, chunk by chunk from the start
        (:class:`~dq_fk_ros.bag.ros1_scan.Ros1ChunkScan`).
        """
        from dq_fk_ros.bag.decompress import bound_rosbags
        from dq_fk_ros.bag.ros1_scan import Ros1ChunkScan
        from rosbags.rosbag1 import Reader, ReaderError
        from rosbags.typesys import get_typestore, Stores
        bound_rosbags()
        self.path = path
        self.note = f'{path}: a ROS 1 bag; its JointState messages are converted to ROS 2'
        self._ros1 = get_typestore(Stores.ROS1_NOETIC)
        self._ros2 = get_typestore(Stores.ROS2_JAZZY)
        self._reader = None if scan else Reader(path)
        try:
            if self._reader is not None:
                self._reader.open()
        except (ReaderError, OSError, ValueError, KeyError, AssertionError, struct.error,
                MemoryError, OverflowError) as exc:
            self._reader = None
            self.note = (f'{path}: a ROS 1 bag whose index cannot be read '
                         f'({one_line(exc)}); read chunk by chunk, its JointState messages '
                         f'converted to ROS 2')
        if self._reader is None:
            try:
                self._scan = Ros1ChunkScan(path, JOINT_STATE)
            except Exception as exc:  # not a bag after all, or unreadable
                raise BagError(f'{path}: not a readable ROS 1 bag ({one_line(exc)})') \
                    from None
            source = self._scan
            self.all_topics = self._scan.all_topics
            self.damage = self._scan.damage
        else:
            self._scan = None
            source = self._reader
            self.all_topics = [(c.topic, c.msgtype) for c in self._reader.connections]
            self.damage = None
        self.connections = [c for c in source.connections if c.msgtype == JOINT_STATE]
        self.start_time = source.start_time if self.connections else 0
        self.end_time = source.end_time if self.connections else 0

    def fallback(self):
        """Return the chunk-by-chunk reader of the same bag (rosbags stopped inside it)."""
        return Ros1Bag(self.path, scan=True) if self._scan is None else None

    def close(self):
        """Close the bag file."""
        (self._reader or self._scan).close()

    def messages(self, connections=None, start=None, stop=None):
        """Yield ``(connection, log_time_ns, cdr)`` of the JointState topics."""
        conns = self.connections if connections is None else connections
        types = self._ros2.types
        js, header, stamp = (types['sensor_msgs/msg/JointState'], types['std_msgs/msg/Header'],
                             types['builtin_interfaces/msg/Time'])
        if self._scan is not None:
            raws = ((c, t, raw) for c, t, raw in self._scan.raw_messages(conns)
                    if (start is None or t >= start) and (stop is None or t < stop))
        else:
            raws = self._reader.messages(connections=conns, start=start, stop=stop)
        for conn, log_time, raw in raws:
            try:
                old = self._ros1.deserialize_ros1(raw, JOINT_STATE)
                msg = js(header=header(stamp=stamp(sec=old.header.stamp.sec,
                                                   nanosec=old.header.stamp.nanosec),
                                       frame_id=old.header.frame_id),
                         name=old.name, position=old.position, velocity=old.velocity,
                         effort=old.effort)
                data = self._ros2.serialize_cdr(msg, JOINT_STATE)
            except Exception:  # a damaged message: let the CDR reader count it malformed
                data = b''
            yield conn, log_time, memoryview(data)


def joint_state_connections(reader, path, topic=None):
    """
    Return the connections of the JointState topic (``topic``, or the only one).

    Raises :class:`BagError`, or :class:`BagDamaged` when the topic is missing from a bag
    whose damage may have taken its definition.
    """
    try:
        return _joint_state_connections(reader, path, topic)
    except BagError as exc:
        damage = getattr(reader, 'damage', None)
        if damage:
            raise BagDamaged(f'{exc}; {damage}') from None
        raise


def _joint_state_connections(reader, path, topic):
    topics = getattr(reader, 'all_topics', [(c.topic, c.msgtype) for c in reader.connections])
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
