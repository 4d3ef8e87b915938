"""
ROS 2 message definitions as text, as a bag's (and a Foxglove channel's) schema holds them.

The ``ros2msg`` text of a type and of every type it uses (``====`` / ``MSG: pkg/Name``
sections), from rosbags' Jazzy type store: what rosbag2 writes into an MCAP schema record
and what Foxglove reads to decode CDR (dq_fk_foxglove's channels).
"""

import functools


@functools.lru_cache(maxsize=32)
def ros2msg_definition(msgtype: str) -> str:
    """
    Return the ``ros2msg`` definition of ``msgtype`` (``tf2_msgs/msg/TFMessage``) with its uses.

    :raises KeyError: a type the Jazzy type store does not know.
    """
    from rosbags.typesys import get_typestore, Stores
    store = get_typestore(Stores.ROS2_JAZZY)
    if msgtype not in store.fielddefs:
        raise KeyError(msgtype)
    return store.generate_msgdef(msgtype)[0]


__all__ = ['ros2msg_definition']
