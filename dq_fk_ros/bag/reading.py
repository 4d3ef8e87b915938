"""
Reading joint-state bags: rosbags' ``Reader``, or a damaged recording record by record.

:func:`open_reader` opens a rosbag2 folder (MCAP or sqlite3) or a bare ``.mcap`` file;
:func:`joint_state_connections` finds the ``sensor_msgs/JointState`` topic in it. Problems
with a bag are :class:`BagError`, whose message is one line for the user.
"""

import os
import re

JOINT_STATE = 'sensor_msgs/msg/JointState'


class BagError(Exception):
    """A bag problem for the user; the message is one line."""


def open_reader(path):
    """
    Open a bag for reading: rosbags' ``Reader``, or its MCAP files record by record.

    A rosbag2 folder rosbags cannot open (no ``metadata.yaml``, no MCAP summary: a
    recording that did not stop cleanly) and a bare ``.mcap`` file are read with
    :class:`~dq_fk_ros.bag.mcap_stream.McapStreamBag`, which keeps every complete record; its
    ``note`` says so and its ``damage`` where reading stops. Raises :class:`BagError`.
    """
    from rosbags.rosbag2 import Reader, ReaderError
    if not os.path.exists(path):
        raise BagError(f'{path}: no such bag')
    if os.path.isfile(path) and str(path).endswith('.mcap'):
        return _stream_bag([path], path, None)
    try:
        reader = Reader(path)
        reader.open()
    except (ReaderError, OSError, ValueError, KeyError) as exc:
        mcaps = _mcap_files(path)
        if not mcaps:
            raise BagError(f'{path}: not a readable rosbag2 ({exc})') from None
        if not os.path.exists(os.path.join(path, 'metadata.yaml')):
            exc = 'no metadata.yaml'
        return _stream_bag(mcaps, path, exc)
    reader.note = reader.damage = None
    return reader


def _mcap_files(folder):
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
    return bag


def joint_state_connections(reader, path, topic=None):
    """Return the connections of the JointState topic (``topic``, or the only one)."""
    listing = ', '.join(f'{c.topic} ({c.msgtype})' for c in reader.connections) or 'none'
    if topic is not None:
        conns = [c for c in reader.connections if c.topic == topic]
        if not conns:
            raise BagError(f'{path} has no topic {topic!r}; its topics: {listing}')
        wrong = [c.msgtype for c in conns if c.msgtype != JOINT_STATE]
        if wrong:
            raise BagError(f'{path}: topic {topic!r} has type {wrong[0]}, not {JOINT_STATE}')
        return conns
    conns = [c for c in reader.connections if c.msgtype == JOINT_STATE]
    topics = sorted({c.topic for c in conns})
    if not topics:
        raise BagError(f'{path} has no {JOINT_STATE} topic; its topics: {listing}')
    if len(topics) > 1:
        raise BagError(f'{path} has several JointState topics ({", ".join(topics)}); '
                       f'pick one with --topic')
    return conns
