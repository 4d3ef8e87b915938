"""
What every bag reader offers (:class:`BagReader`), below the adapters that implement it.

The adapters (``rosbag2_reader``, ``mcap_stream``, ``ros1_bag``) import this module; the
registry of formats that picks one (:mod:`dq_fk_ros.storage.reading`) imports them.
"""

from dataclasses import dataclass
import os
import re
import stat
from typing import Iterator, Optional, Protocol, runtime_checkable, Sequence

import numpy as np

JOINT_STATE = 'sensor_msgs/msg/JointState'
TF_MESSAGE = 'tf2_msgs/msg/TFMessage'
BATCH = 4096    # messages a batch


@dataclass
class MessageBatch:
    """
    Messages in reading order, their bytes back to back in ``data`` (no object per message).

    ``connection_ids``, ``log_times``, ``starts``, ``lengths``: ``(n,)`` int64: the id of
    each message's connection, its log time (ns), where its bytes start in ``data``, how many.
    """

    connection_ids: np.ndarray
    log_times: np.ndarray
    data: bytes
    starts: np.ndarray
    lengths: np.ndarray

    def __len__(self) -> int:
        """Return the number of messages."""
        return len(self.log_times)

    def raw(self, i: int) -> memoryview:
        """Return message ``i``'s bytes."""
        start = int(self.starts[i])
        return memoryview(self.data)[start:start + int(self.lengths[i])]


@runtime_checkable
class BagReader(Protocol):
    """
    What every bag adapter offers (rosbags' ``Reader`` surface, plus how it was read).

    ``connections`` are rosbags ``Connection`` tuples (``msgcount`` filled), ``all_topics``
    ``(topic, type)`` of every topic in the bag (a ROS 1 reader offers only its JointState
    connections). Times are log times in ns, ``end_time`` past the last message.
    """

    connections: list
    all_topics: list
    start_time: int
    end_time: int
    note: Optional[str]          # one line for the user on how the bag is read, or None
    damage: Optional[str]        # one line: what was damaged and skipped, or None
    copies_messages: bool        # its messages of every topic can be copied as they are
    windowable: bool             # an indexed rosbag2 the fleet may cut into time windows

    def messages(self, connections: Optional[Sequence] = None, start: Optional[int] = None,
                 stop: Optional[int] = None) -> Iterator[tuple]:
        """Yield ``(connection, log_time_ns, raw CDR bytes)``, ``start <= t < stop``."""

    def message_batches(self, connections: Optional[Sequence] = None,
                        start: Optional[int] = None, stop: Optional[int] = None,
                        size: int = BATCH) -> Iterator[MessageBatch]:
        """Yield the same messages as :meth:`messages`, ``size`` a batch (the last fewer)."""

    def fallback(self) -> Optional['BagReader']:
        """Return a reader of the same bag that skips damage (rosbags stopped), or None."""

    def close(self) -> None:
        """Release the bag's files."""


class BatchesFromMessages:
    """
    ``message_batches`` made from ``messages``: for the adapters that read a message at a time.

    The reference of a reader's own batches
    (:class:`~dq_fk_ros.storage.mcap_chunks.McapChunkReader`).
    """

    def message_batches(self, connections=None, start=None, stop=None,
                        size=BATCH) -> Iterator[MessageBatch]:
        """
        Yield :meth:`messages` ``size`` at a time as :class:`MessageBatch` es.

        A reading that fails hands on the messages read before it, then raises.
        """
        ids, times, raws = [], [], []
        try:
            for conn, log_time, raw in self.messages(connections, start, stop):
                ids.append(conn.id)
                times.append(log_time)
                raws.append(raw)
                if len(raws) == size:
                    yield batch_of(ids, times, raws)
                    ids, times, raws = [], [], []
        except Exception:
            if raws:
                yield batch_of(ids, times, raws)
            raise
        if raws:
            yield batch_of(ids, times, raws)


def batch_of(ids, log_times, raws) -> MessageBatch:
    """Return the :class:`MessageBatch` of messages given one by one."""
    lengths = np.fromiter(map(len, raws), np.int64, len(raws))
    starts = np.zeros(len(raws), np.int64)
    np.cumsum(lengths[:-1], out=starts[1:])
    return MessageBatch(np.array(ids, np.int64), np.array(log_times, np.int64),
                        b''.join(raws), starts, lengths)


def check_bag_files(path) -> None:
    """
    Refuse a bag that is, or holds, something other than regular files (one-line BagError).

    A FIFO or device named like a bag file (or ``metadata.yaml``) would block every reader
    that opens it, for ever; links are followed (a link to a bag file is a bag file).
    """
    from dq_fk_ros.errors import BagError
    path = os.fspath(path)
    try:
        mode = os.stat(path).st_mode
        names = sorted(os.listdir(path)) if stat.S_ISDIR(mode) else None
    except OSError as exc:
        raise BagError(f'{path}: cannot be read ({exc.strerror})') from None
    if names is None:
        if not stat.S_ISREG(mode):
            raise BagError(f'{path}: not a regular file (a FIFO or a device); a bag is files')
        return
    for name in names:
        inner = os.path.join(path, name)
        try:
            mode = os.stat(inner).st_mode
        except OSError:
            continue    # a dangling link: the readers say so if they need it
        if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
            raise BagError(f'{inner}: not a regular file (a FIFO or a device); a bag is files')


def mcap_folder_files(folder) -> list:
    """List the MCAP files of a bag folder, splits in order (``x_2`` before ``x_10``)."""
    if not os.path.isdir(folder):
        return []
    names = [n for n in os.listdir(folder) if n.endswith('.mcap')]
    split = re.compile(r'^(.*?)(\d*)\.mcap$')
    return [os.path.join(folder, n) for n in sorted(
        names, key=lambda n: (split.match(n)[1], int(split.match(n)[2] or -1)))]
