"""tf2_ros.buffer: dq_fk_ros.ros.tf_buffer (a re-export)."""

from dq_fk_ros.ros.tf_buffer import Buffer  # noqa: F401

__all__ = ['Buffer']
