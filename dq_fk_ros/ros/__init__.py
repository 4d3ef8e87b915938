"""
ROS layer: the rclpy nodes and everything that touches rclpy or message classes.

:mod:`.conversions` owns the conversion between the core's arrays and ROS messages.
"""
