"""tf2_py for code written for it, on dq_fk_ros (``dq_fk tf compat-path``; docs/tf.md)."""

from dq_fk_ros.ros.tf_message_core import MessageBufferCore as BufferCore  # noqa: F401
from dq_fk_ros.transforms.exceptions import *  # noqa: F401,F403
from dq_fk_ros.transforms.exceptions import __all__ as _exceptions

__all__ = ['BufferCore'] + _exceptions
