"""
A bag of joint states to try the bag tools on: ``dq_fk_bag example``.

rosbag2 (MCAP) with one ``/joint_states`` topic of ``sensor_msgs/JointState``, serialized
with rosbags' Jazzy types; the motion comes from the caller (``positions(t)``).
"""

import numpy as np

JOINT_STATE = 'sensor_msgs/msg/JointState'
START_NS = 1_700_000_000_000_000_000  # the first message's stamp (2023-11-14)


def write_example_bag(path, joint_names, sample, seconds=10.0, rate_hz=100.0) -> int:
    """
    Write ``seconds`` of joint states at ``rate_hz`` to a new bag at ``path``; return the count.

    :param sample: ``sample(t_s) -> (positions, velocities)`` in ``joint_names`` order.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import get_typestore, Stores
    store = get_typestore(Stores.ROS2_JAZZY)
    types = store.types
    count = int(round(seconds * rate_hz))
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection('/joint_states', JOINT_STATE, typestore=store)
        for k in range(count):
            t_s = k / rate_hz
            stamp = START_NS + int(round(t_s * 1e9))
            positions, velocities = sample(t_s)
            time = types['builtin_interfaces/msg/Time'](sec=stamp // 10**9,
                                                        nanosec=stamp % 10**9)
            header = types['std_msgs/msg/Header'](stamp=time, frame_id='')
            msg = types[JOINT_STATE](header=header, name=list(joint_names),
                                     position=np.asarray(positions, dtype=float),
                                     velocity=np.asarray(velocities, dtype=float),
                                     effort=np.zeros(0))
            writer.write(conn, stamp, bytes(store.serialize_cdr(msg, JOINT_STATE)))
    return count


__all__ = ['write_example_bag']
