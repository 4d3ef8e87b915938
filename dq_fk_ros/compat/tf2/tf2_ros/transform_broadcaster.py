"""tf2_ros.transform_broadcaster: dq_fk_ros.ros.tf_broadcasters (a re-export)."""

from dq_fk_ros.ros.tf_broadcasters import TransformBroadcaster  # noqa: F401

__all__ = ['TransformBroadcaster']
