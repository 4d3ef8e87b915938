"""
Messages layer: ROS message content without rclpy.

The node's joint-state input rules (:mod:`.joint_states`) and the CDR wire format of the
messages the package reads and writes (:mod:`.cdr`), in plain numpy.
"""
