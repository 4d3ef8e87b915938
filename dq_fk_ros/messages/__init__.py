"""
Messages layer: ROS message content without rclpy.

The node's joint-state input rules (:mod:`.joint_states`, :mod:`.merge_state`), the one
way a serialized message is taken in (:mod:`.joint_state_input`), the CDR wire format of
the messages the package reads and writes (:mod:`.cdr`), and the output table and plan
(:mod:`.outputs`, :mod:`.output_plan`), in plain numpy.
"""
