"""
ROS layer: the rclpy nodes and tools (dq_fk_node, fake_joint_publisher, TF, bag play).

:mod:`.conversions` owns the conversion between the core's arrays and ROS messages; the
viewers (dq_fk_view, dq_fk_foxglove) are the layer above, :mod:`dq_fk_ros.viewers`.
"""
