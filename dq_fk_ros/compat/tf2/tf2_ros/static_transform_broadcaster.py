"""tf2_ros.static_transform_broadcaster: dq_fk_ros.ros.tf_broadcasters (a re-export)."""

from dq_fk_ros.ros.tf_broadcasters import StaticTransformBroadcaster  # noqa: F401

__all__ = ['StaticTransformBroadcaster']
