"""A ROS 1 bag as a :class:`~dq_fk_ros.storage.reader_interface.BagReader`, in ROS 2 CDR."""

import struct
from typing import Iterator, Optional

from dq_fk_ros.errors import BagError
from dq_fk_ros.storage.reader_interface import BatchesFromMessages, JOINT_STATE, TF_MESSAGE
from dq_fk_ros.storage.text import one_line

ROS1_TF_TYPES = (TF_MESSAGE, 'tf/msg/tfMessage')   # tf2's, and tf's in older bags


class Ros1Bag(BatchesFromMessages):
    """
    A ROS 1 bag, with its messages of one type converted to ROS 2 CDR as they are read.

    A :class:`~dq_fk_ros.storage.reader_interface.BagReader`. The topics of ``msgtype`` only
    (JointState, or ``tf2_msgs/msg/TFMessage`` for TF): other ROS 1 types would need a
    conversion of their own (``rosbags-convert``, installed with rosbags, converts a whole
    ROS 1 bag to rosbag2).
    """

    copies_messages = False   # its messages are ROS 1 bytes: only JointStates are converted
    windowable = False

    def __init__(self, path, scan=False, msgtype=JOINT_STATE):
        """
        Open the bag; raises :class:`BagError` if it cannot be read at all.

        Through its index with rosbags; if that fails (a damaged, cut-off or misplaced
        index), or with ``scan``, chunk by chunk from the start
        (:class:`~dq_fk_ros.storage.ros1_scan.Ros1ChunkScan`).
        """
        from dq_fk_ros.storage.decompress import bound_rosbags
        from dq_fk_ros.storage.ros1_scan import Ros1ChunkScan
        from rosbags.rosbag1 import Reader, ReaderError
        from rosbags.typesys import get_typestore, Stores
        bound_rosbags(ros1=True)
        self.path = path
        self.msgtype = msgtype
        what = 'JointState' if msgtype == JOINT_STATE else msgtype.rsplit('/', 1)[-1]
        self.note = f'{path}: a ROS 1 bag; its {what} messages are converted to ROS 2'
        self._ros1 = get_typestore(Stores.ROS1_NOETIC)
        self._ros2 = get_typestore(Stores.ROS2_JAZZY)
        self._types = (msgtype,)
        if msgtype == TF_MESSAGE:   # ROS 1 has tf2's TFMessage and tf's older tfMessage
            from rosbags.typesys import get_types_from_msg
            for name in ROS1_TF_TYPES:
                self._ros1.register(get_types_from_msg(
                    'geometry_msgs/TransformStamped[] transforms', name))
            self._types = ROS1_TF_TYPES
        self._reader = None if scan else Reader(path)
        try:
            if self._reader is not None:
                self._reader.open()
        except (ReaderError, OSError, ValueError, KeyError, AssertionError, struct.error,
                MemoryError, OverflowError) as exc:
            self._reader = None
            self.note = (f'{path}: a ROS 1 bag whose index cannot be read '
                         f'({one_line(exc)}); read chunk by chunk, its {what} messages '
                         f'converted to ROS 2')
        if self._reader is None:
            try:
                self._scan = Ros1ChunkScan(path, self._types)
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
        self.connections = [c for c in source.connections if c.msgtype in self._types]
        self.start_time = source.start_time if self.connections else 0
        self.end_time = source.end_time if self.connections else 0

    def fallback(self) -> Optional['Ros1Bag']:
        """Return the chunk-by-chunk reader of the same bag (rosbags stopped inside it)."""
        return Ros1Bag(self.path, scan=True, msgtype=self.msgtype) if self._scan is None \
            else None

    def close(self) -> None:
        """Close the bag file."""
        (self._reader or self._scan).close()

    def messages(self, connections=None, start=None, stop=None) -> Iterator[tuple]:
        """Yield ``(connection, log_time_ns, cdr)`` of the topics of its type."""
        conns = self.connections if connections is None else connections
        convert = self._tf if self.msgtype == TF_MESSAGE else self._joint_state
        if self._scan is not None:
            raws = ((c, t, raw) for c, t, raw in self._scan.raw_messages(conns)
                    if (start is None or t >= start) and (stop is None or t < stop))
        else:
            raws = self._reader.messages(connections=conns, start=start, stop=stop)
        for conn, log_time, raw in raws:
            self._tf_type = conn.msgtype
            try:
                data = convert(raw)
            except Exception:  # a damaged message: let the CDR reader count it malformed
                data = b''
            yield conn, log_time, memoryview(data)

    def _joint_state(self, raw):
        types = self._ros2.types
        old = self._ros1.deserialize_ros1(raw, JOINT_STATE)
        msg = types['sensor_msgs/msg/JointState'](
            header=self._header(old.header), name=old.name, position=old.position,
            velocity=old.velocity, effort=old.effort)
        return self._ros2.serialize_cdr(msg, JOINT_STATE)

    def _header(self, old):
        types = self._ros2.types
        return types['std_msgs/msg/Header'](
            stamp=types['builtin_interfaces/msg/Time'](sec=old.stamp.sec,
                                                       nanosec=old.stamp.nanosec),
            frame_id=old.frame_id)

    def _tf(self, raw):
        types = self._ros2.types
        old = self._ros1.deserialize_ros1(raw, self._tf_type)
        stamped = types['geometry_msgs/msg/TransformStamped']
        msg = types[TF_MESSAGE](transforms=[
            stamped(header=self._header(t.header), child_frame_id=t.child_frame_id,
                    transform=t.transform) for t in old.transforms])
        return self._ros2.serialize_cdr(msg, TF_MESSAGE)
