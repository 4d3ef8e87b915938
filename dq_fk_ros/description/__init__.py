"""
Description layer: the YAML robot description, URDF read (and cut into DH chains) and written.

Built on :mod:`dq_fk_ros.kinematics`; no ROS.
"""
