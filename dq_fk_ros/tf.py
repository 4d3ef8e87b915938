"""
TF read back without tf2, under tf2_ros's names: ``from dq_fk_ros import tf as tf2_ros``.

``Buffer`` (:mod:`dq_fk_ros.ros.tf_buffer`), ``TransformListener``
(:mod:`dq_fk_ros.ros.tf_listener`), ``TransformBroadcaster``, ``StaticTransformBroadcaster``
(:mod:`dq_fk_ros.ros.tf_broadcasters`), ``BufferClient``
(:mod:`dq_fk_ros.ros.tf_buffer_client`), the registrations ``Buffer.transform`` uses
(:mod:`dq_fk_ros.ros.tf_registration`) and tf2's exceptions
(:mod:`dq_fk_ros.transforms.exceptions`): rclpy types. The storage and the rules without ROS
are :class:`dq_fk_ros.transforms.buffer_core.BufferCore` (integer ns, pose tuples).
docs/tf.md has the tf2_ros -> dq_fk_ros.tf table, and the compat path
(``dq_fk tf compat-path``) that makes ``import tf2_ros`` itself find these.
"""

from dq_fk_ros.ros.tf_broadcasters import StaticTransformBroadcaster, TransformBroadcaster
from dq_fk_ros.ros.tf_buffer import Buffer, buffer_from_bag
from dq_fk_ros.ros.tf_buffer_client import BufferClient
from dq_fk_ros.ros.tf_listener import TransformListener
from dq_fk_ros.ros.tf_registration import (BufferInterface, convert, ConvertRegistration,
                                           NotImplementedException, Stamped,
                                           TransformRegistration, TypeException)
from dq_fk_ros.transforms.buffer_core import BufferCore
from dq_fk_ros.transforms.exceptions import (ConnectivityException, ExtrapolationException,
                                             InvalidArgumentException, LookupException,
                                             TimeoutException, TransformException)


__all__ = ['Buffer', 'buffer_from_bag', 'BufferClient', 'BufferCore', 'BufferInterface',
           'ConnectivityException', 'convert', 'ConvertRegistration', 'ExtrapolationException',
           'InvalidArgumentException', 'LookupException', 'NotImplementedException', 'Stamped',
           'StaticTransformBroadcaster', 'TimeoutException', 'TransformBroadcaster',
           'TransformException', 'TransformListener', 'TransformRegistration', 'TypeException']
