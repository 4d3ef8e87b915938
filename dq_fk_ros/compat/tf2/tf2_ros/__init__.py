"""tf2_ros for code written for it, on dq_fk_ros (``dq_fk tf compat-path``; docs/tf.md)."""

from dq_fk_ros.ros.tf_broadcasters import (StaticTransformBroadcaster,  # noqa: F401
                                           TransformBroadcaster)
from dq_fk_ros.ros.tf_buffer import Buffer  # noqa: F401
from dq_fk_ros.ros.tf_buffer_client import BufferClient  # noqa: F401
from dq_fk_ros.ros.tf_listener import TransformListener  # noqa: F401
from dq_fk_ros.ros.tf_registration import *  # noqa: F401,F403
from dq_fk_ros.ros.tf_registration import __all__ as _registration
from dq_fk_ros.transforms.exceptions import *  # noqa: F401,F403
from dq_fk_ros.transforms.exceptions import __all__ as _exceptions

__all__ = ['Buffer', 'BufferClient', 'StaticTransformBroadcaster', 'TransformBroadcaster',
           'TransformListener'] + _registration + _exceptions
