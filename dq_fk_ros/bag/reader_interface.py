"""
What every bag reader offers (:class:`BagReader`), below the adapters that implement it.

The adapters (``rosbag2_reader``, ``mcap_stream``, ``ros1_bag``) import this module; the
registry of formats that picks one (:mod:`dq_fk_ros.bag.reading`) imports them.
"""

import os
import re
from typing import Iterator, Optional, Protocol, runtime_checkable, Sequence

JOINT_STATE = 'sensor_msgs/msg/JointState'


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

    def fallback(self) -> Optional['BagReader']:
        """Return a reader of the same bag that skips damage (rosbags stopped), or None."""

    def close(self) -> None:
        """Release the bag's files."""


def mcap_folder_files(folder) -> list:
    """List the MCAP files of a bag folder, splits in order (``x_2`` before ``x_10``)."""
    if not os.path.isdir(folder):
        return []
    names = [n for n in os.listdir(folder) if n.endswith('.mcap')]
    split = re.compile(r'^(.*?)(\d*)\.mcap$')
    return [os.path.join(folder, n) for n in sorted(
        names, key=lambda n: (split.match(n)[1], int(split.match(n)[2] or -1)))]
