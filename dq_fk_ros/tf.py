"""
TF read back without tf2, under tf2_ros's names: ``from dq_fk_ros import tf as tf2_ros``.

``Buffer``, ``TransformListener``, ``TransformBroadcaster``, ``StaticTransformBroadcaster``
(:mod:`dq_fk_ros.ros.tf_buffer`, rclpy types) and tf2's exceptions
(:mod:`dq_fk_ros.transforms.exceptions`); the storage and the rules without ROS are
:class:`dq_fk_ros.transforms.buffer_core.BufferCore` (integer ns, pose tuples). docs/tf.md
has the tf2_ros -> dq_fk_ros.tf table.
"""

from dq_fk_ros.ros.tf_buffer import (Buffer, buffer_from_bag, StaticTransformBroadcaster,
                                     TransformBroadcaster, TransformListener)
from dq_fk_ros.transforms.buffer_core import BufferCore
from dq_fk_ros.transforms.exceptions import (ConnectivityException, ExtrapolationException,
                                             InvalidArgumentException, LookupException,
                                             TimeoutException, TransformException)

__all__ = ['Buffer', 'buffer_from_bag', 'BufferCore', 'ConnectivityException',
           'ExtrapolationException', 'InvalidArgumentException', 'LookupException',
           'StaticTransformBroadcaster', 'TimeoutException', 'TransformBroadcaster',
           'TransformException', 'TransformListener']
