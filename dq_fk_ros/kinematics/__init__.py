"""Kinematics layer: dual quaternions, DH chains and trees (tables, engines), twists; no ROS."""
