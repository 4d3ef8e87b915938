"""tf2_py._tf2_py: tf2_py's BufferCore and exceptions, from dq_fk_ros (a re-export)."""

from dq_fk_ros.ros.tf_message_core import MessageBufferCore as BufferCore  # noqa: F401
from dq_fk_ros.transforms.exceptions import *  # noqa: F401,F403
from dq_fk_ros.transforms.exceptions import __all__ as _exceptions

__all__ = ['BufferCore'] + _exceptions
