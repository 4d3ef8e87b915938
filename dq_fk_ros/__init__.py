"""
Dual-quaternion forward kinematics from a DH table, published to ROS 2.

The numerical core (:mod:`dq_fk_ros.dual_quaternion`, :mod:`dq_fk_ros.dh`) is plain numpy
and imports nothing from ROS; :mod:`dq_fk_ros.node` is the rclpy glue.
"""
