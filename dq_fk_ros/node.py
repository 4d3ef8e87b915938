"""
The dq_fk_node executable: JointState in, link-frame poses out.

This is the ROS 2 glue only; kinematics live in :mod:`dq_fk_ros.dh`.
"""

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from sensor_msgs.msg import JointState


class DqFkNode(Node):
    """Subscribe to ``joint_states``; publishing of link frames is added by the node issue."""

    def __init__(self):
        super().__init__('dq_fk_node')
        self._joint_state_sub = self.create_subscription(
            JointState, 'joint_states', self._on_joint_state, 10)
        self.get_logger().info('dq_fk_node started')

    def _on_joint_state(self, msg):
        pass


def main(args=None):
    """Run dq_fk_node until SIGINT/SIGTERM (as ``ros2 run dq_fk_ros dq_fk_node``)."""
    rclpy.init(args=args)
    node = None
    try:
        node = DqFkNode()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
