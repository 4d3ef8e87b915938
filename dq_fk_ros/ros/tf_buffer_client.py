"""
tf2_ros's ``BufferClient``: lookups asked of a buffer server (``tf2_msgs/action/LookupTransform``).

As geometry2's ``tf2_ros_py/tf2_ros/buffer_client.py``: a goal per lookup to the action
server ``ns`` (tf2_ros's ``buffer_server``, or any server of that action), the server's
``TF2Error`` raised as tf2's exception of that code, ``transform`` and ``transform_full``
from :class:`~dq_fk_ros.ros.tf_registration.BufferInterface`. The node must be spun by the
caller (another thread, as tf2_ros requires).

Not as tf2_ros: each wait is for the goal's future with a deadline (the lookup's ``timeout``
plus ``timeout_padding``), the result's too (tf2_ros waits for the result without one), and
no thread is started per lookup.
"""

import threading

from dq_fk_ros.ros.tf_message_core import time_ns
from dq_fk_ros.ros.tf_registration import BufferInterface
from dq_fk_ros.transforms.exceptions import (ConnectivityException, ExtrapolationException,
                                             InvalidArgumentException, LookupException,
                                             TimeoutException, TransformException)
from geometry_msgs.msg import TransformStamped
from rclpy.action import ActionClient
from rclpy.duration import Duration
from rclpy.time import Time
from tf2_msgs.action import LookupTransform
from tf2_msgs.msg import TF2Error

ERRORS = {TF2Error.LOOKUP_ERROR: LookupException,
          TF2Error.CONNECTIVITY_ERROR: ConnectivityException,
          TF2Error.EXTRAPOLATION_ERROR: ExtrapolationException,
          TF2Error.INVALID_ARGUMENT_ERROR: InvalidArgumentException,
          TF2Error.TIMEOUT_ERROR: TimeoutException}


def _time_message(value):
    return Time(nanoseconds=time_ns(value)).to_msg()


def _wait(future, seconds: float) -> bool:
    """Return whether ``future`` is done within ``seconds`` (woken by its done callback)."""
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    return done.wait(max(0.0, seconds)) or future.done()


class BufferClient(BufferInterface):
    """
    tf2_ros's ``BufferClient`` (module doc).

    :param node: the node the action client is made on (spun elsewhere).
    :param ns: the action's name (tf2_ros's ``buffer_server`` offers ``tf2_buffer_server``).
    :param check_frequency: accepted as tf2_ros's; the waits here are woken by the futures.
    :param timeout_padding: added to each lookup's timeout for the round trip (``Duration``).
    """

    def __init__(self, node, ns: str, check_frequency: float = 10.0,
                 timeout_padding=Duration(seconds=2.0)):
        """Make the action client."""
        BufferInterface.__init__(self)
        self.node = node
        self.action_client = ActionClient(node, LookupTransform, action_name=ns)
        self.check_frequency = check_frequency
        self.timeout_padding = timeout_padding

    def lookup_transform(self, target_frame, source_frame, time,
                         timeout=Duration()) -> TransformStamped:
        """Return ``source_frame`` in ``target_frame`` at ``time``, asked of the server."""
        goal = LookupTransform.Goal(target_frame=target_frame, source_frame=source_frame,
                                    source_time=_time_message(time), timeout=timeout.to_msg(),
                                    advanced=False)
        return self._process_goal(goal, timeout)

    def lookup_transform_full(self, target_frame, target_time, source_frame, source_time,
                              fixed_frame, timeout=Duration()) -> TransformStamped:
        """Return ``source_frame`` at ``source_time`` in ``target_frame`` at ``target_time``."""
        goal = LookupTransform.Goal(target_frame=target_frame, source_frame=source_frame,
                                    source_time=_time_message(source_time),
                                    target_time=_time_message(target_time),
                                    fixed_frame=fixed_frame, timeout=timeout.to_msg(),
                                    advanced=True)
        return self._process_goal(goal, timeout)

    def can_transform(self, target_frame, source_frame, time, timeout=Duration()) -> bool:
        """Return whether the server gives the transform."""
        try:
            self.lookup_transform(target_frame, source_frame, time, timeout)
            return True
        except TransformException:
            return False

    def can_transform_full(self, target_frame, target_time, source_frame, source_time,
                           fixed_frame, timeout=Duration()) -> bool:
        """Return whether the server gives the transform via ``fixed_frame``."""
        try:
            self.lookup_transform_full(target_frame, target_time, source_frame, source_time,
                                       fixed_frame, timeout)
            return True
        except TransformException:
            return False

    def _process_goal(self, goal, timeout):
        if not self.action_client.server_is_ready():
            raise TimeoutException('The BufferServer is not ready.')
        seconds = (timeout.nanoseconds + self.timeout_padding.nanoseconds) / 1e9
        sent = self.action_client.send_goal_async(goal)
        if not _wait(sent, seconds):
            raise TimeoutException('The LookupTransform goal sent to the BufferServer did not '
                                   'come back in the specified time. Something is likely '
                                   'wrong with the server.')
        handle = sent.result()
        if not handle.accepted:
            raise TimeoutException('The LookupTransform goal sent to the BufferServer did not '
                                   'come back with accepted status. Something is likely '
                                   'wrong with the server.')
        result = handle.get_result_async()
        if not _wait(result, seconds):
            raise TimeoutException('The BufferServer did not send the LookupTransform result '
                                   'in the specified time.')
        return self._process_result(result.result().result)

    @staticmethod
    def _process_result(result):
        if result is None or result.error is None:
            raise TransformException('The BufferServer returned None for result or '
                                     'result.error!  Something is likely wrong with the '
                                     'server.')
        code = result.error.error
        if code != TF2Error.NO_ERROR:
            raise ERRORS.get(code, TransformException)(result.error.error_string)
        return result.transform

    def destroy(self) -> None:
        """Destroy the action client."""
        self.action_client.destroy()


__all__ = ['BufferClient']
