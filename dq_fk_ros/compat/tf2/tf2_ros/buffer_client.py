"""tf2_ros.buffer_client: dq_fk_ros.ros.tf_buffer_client (a re-export)."""

from dq_fk_ros.ros.tf_buffer_client import BufferClient  # noqa: F401

__all__ = ['BufferClient']
