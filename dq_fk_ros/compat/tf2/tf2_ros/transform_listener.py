"""tf2_ros.transform_listener: dq_fk_ros.ros.tf_listener (a re-export)."""

from dq_fk_ros.ros.tf_listener import TransformListener  # noqa: F401

__all__ = ['TransformListener']
