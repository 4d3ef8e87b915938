"""
The message types ``dq_fk_bag process`` writes: their ``ros2msg`` definitions and RIHS01 hashes.

What an output bag's schemas and ``metadata.yaml`` carry for ``/tf``, ``/tf_static``, the pose
and twist topics and ``/robot_description``, as rosbags' Jazzy type store makes them
(``generate_msgdef``, ``hash_rihs01``). Kept here so that processing a bag does not build
that store (tens of milliseconds a process); test_output_types.py holds them equal to the
store's. A new output type: its entry here, printed by ``python -m dq_fk_ros.bag.output_types
TYPE``.
"""

import struct
import sys

# msgtype -> (definition, RIHS01 hash)
OUTPUT_TYPES = {
    'geometry_msgs/msg/TwistStamped': (
        'std_msgs/Header header\n'
        'geometry_msgs/Twist twist\n'
        '================================================================================\n'
        'MSG: std_msgs/Header\n'
        'builtin_interfaces/Time stamp\n'
        'string frame_id\n'
        '================================================================================\n'
        'MSG: builtin_interfaces/Time\n'
        'int32 sec\n'
        'uint32 nanosec\n'
        '================================================================================\n'
        'MSG: geometry_msgs/Twist\n'
        'geometry_msgs/Vector3 linear\n'
        'geometry_msgs/Vector3 angular\n'
        '================================================================================\n'
        'MSG: geometry_msgs/Vector3\n'
        'float64 x\n'
        'float64 y\n'
        'float64 z\n',
        'RIHS01_5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64'),
    'geometry_msgs/msg/PoseStamped': (
        'std_msgs/Header header\n'
        'geometry_msgs/Pose pose\n'
        '================================================================================\n'
        'MSG: std_msgs/Header\n'
        'builtin_interfaces/Time stamp\n'
        'string frame_id\n'
        '================================================================================\n'
        'MSG: builtin_interfaces/Time\n'
        'int32 sec\n'
        'uint32 nanosec\n'
        '================================================================================\n'
        'MSG: geometry_msgs/Pose\n'
        'geometry_msgs/Point position\n'
        'geometry_msgs/Quaternion orientation\n'
        '================================================================================\n'
        'MSG: geometry_msgs/Point\n'
        'float64 x\n'
        'float64 y\n'
        'float64 z\n'
        '================================================================================\n'
        'MSG: geometry_msgs/Quaternion\n'
        'float64 x\n'
        'float64 y\n'
        'float64 z\n'
        'float64 w\n',
        'RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8'),
    'std_msgs/msg/String': (
        'string data\n',
        'RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18'),
    'tf2_msgs/msg/TFMessage': (
        'geometry_msgs/TransformStamped[] transforms\n'
        '================================================================================\n'
        'MSG: geometry_msgs/TransformStamped\n'
        'std_msgs/Header header\n'
        'string child_frame_id\n'
        'geometry_msgs/Transform transform\n'
        '================================================================================\n'
        'MSG: std_msgs/Header\n'
        'builtin_interfaces/Time stamp\n'
        'string frame_id\n'
        '================================================================================\n'
        'MSG: builtin_interfaces/Time\n'
        'int32 sec\n'
        'uint32 nanosec\n'
        '================================================================================\n'
        'MSG: geometry_msgs/Transform\n'
        'geometry_msgs/Vector3 translation\n'
        'geometry_msgs/Quaternion rotation\n'
        '================================================================================\n'
        'MSG: geometry_msgs/Vector3\n'
        'float64 x\n'
        'float64 y\n'
        'float64 z\n'
        '================================================================================\n'
        'MSG: geometry_msgs/Quaternion\n'
        'float64 x\n'
        'float64 y\n'
        'float64 z\n'
        'float64 w\n',
        'RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087'),
}


def string_cdr(text: str) -> bytes:
    """Return a ``std_msgs/msg/String`` of ``text`` as little-endian CDR."""
    data = text.encode('utf-8') + b'\x00'
    return b'\x00\x01\x00\x00' + struct.pack('<I', len(data)) + data


def from_typestore(msgtype: str) -> tuple:
    """Return ``(definition, RIHS01 hash)`` of ``msgtype`` from rosbags' Jazzy type store."""
    from rosbags.typesys import get_typestore, Stores
    store = get_typestore(Stores.ROS2_JAZZY)
    return store.generate_msgdef(msgtype, ros_version=2)[0], store.hash_rihs01(msgtype)


if __name__ == '__main__':
    for name in sys.argv[1:]:
        print(repr(name), repr(from_typestore(name)))

__all__ = ['OUTPUT_TYPES', 'from_typestore', 'string_cdr']
