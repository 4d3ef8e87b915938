"""
tf2_ros's ``TransformBroadcaster`` and ``StaticTransformBroadcaster``: transforms out.

``sendTransform`` (tf2_ros's name) and ``send_transform`` take one ``TransformStamped`` or a
list; QoS as tf2_ros's (``/tf`` depth 100; ``/tf_static`` reliable, transient local, depth
1, every static transform sent so far in each message, the newest per child frame).
"""

from dq_fk_ros.ros.tf_listener import DYNAMIC_QOS
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage

STATIC_BROADCASTER_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                                    reliability=ReliabilityPolicy.RELIABLE,
                                    durability=DurabilityPolicy.TRANSIENT_LOCAL)


def _as_list(transform) -> list:
    return list(transform) if isinstance(transform, (list, tuple)) else [transform]


class TransformBroadcaster:
    """tf2_ros's ``TransformBroadcaster``: ``sendTransform`` publishes on ``/tf``."""

    def __init__(self, node, qos=None):
        """Create the ``/tf`` publisher on ``node`` (depth 100, as tf2_ros)."""
        self.pub_tf = node.create_publisher(TFMessage, '/tf', qos or DYNAMIC_QOS)

    def sendTransform(self, transform) -> None:   # noqa: N802 (tf2_ros's name)
        """Publish one ``TransformStamped`` or a list of them."""
        self.pub_tf.publish(TFMessage(transforms=_as_list(transform)))

    send_transform = sendTransform


class StaticTransformBroadcaster:
    """tf2_ros's ``StaticTransformBroadcaster``: every transform sent, latched on /tf_static."""

    def __init__(self, node, qos=None):
        """Create the latched ``/tf_static`` publisher (reliable, transient local, depth 1)."""
        self.pub_tf = node.create_publisher(TFMessage, '/tf_static',
                                            qos or STATIC_BROADCASTER_QOS)
        self._net = {}   # child frame -> its newest transform

    def sendTransform(self, transform) -> None:   # noqa: N802 (tf2_ros's name)
        """Add or replace transforms by child frame; publish all of them (as tf2_ros)."""
        for t in _as_list(transform):
            self._net[t.child_frame_id] = t
        self.pub_tf.publish(TFMessage(transforms=list(self._net.values())))

    send_transform = sendTransform


__all__ = ['StaticTransformBroadcaster', 'STATIC_BROADCASTER_QOS', 'TransformBroadcaster']
