"""
Dual-quaternion forward kinematics from a DH table, published to ROS 2.

Layers, bottom up (a layer imports only those below it; the README's "Architecture"):

* :mod:`dq_fk_ros.kinematics`: dual quaternions and DH chains, numpy only.
* :mod:`dq_fk_ros.description`: the YAML robot description, URDF output.
* :mod:`dq_fk_ros.messages`: joint-state input rules and the CDR wire format, no rclpy.
* :mod:`dq_fk_ros.bag`: rosbag2 files (rosbags, mcap), no rclpy.
* :mod:`dq_fk_ros.ros`: the rclpy nodes and message conversion.
* :mod:`dq_fk_ros.cli`: the ``dq_fk`` and ``dq_fk_bag`` command lines.
"""
