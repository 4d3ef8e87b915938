"""
Description layer: the YAML robot description and the URDF written from it.

Built on :mod:`dq_fk_ros.kinematics`; no ROS.
"""
