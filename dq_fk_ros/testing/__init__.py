"""
Headless tests of code that uses a robot's TF: fixtures and an assertion (docs/testing.md).

The pytest plugin (:mod:`dq_fk_ros.testing.plugin`, registered by the package) gives the
fixtures ``dq_fk_domain``, ``dq_fk_processes`` and ``dq_fk_robot``;
:func:`assert_pose_close` compares two poses; :func:`next_message` waits for a topic's
next message (rclpy imported then, not before); :func:`wait_for_match` for both sides of a
publisher and subscription to match; :func:`wait_until` for a predicate, with a deadline.
"""

from dq_fk_ros.testing.poses import assert_pose_close, pose_difference
from dq_fk_ros.testing.topics import wait_for_match, wait_until


def next_message(msg_type, topic: str, where=None, timeout_s: float = 10.0, qos=10) -> object:
    """Return the next message on ``topic`` that ``where`` accepts (:mod:`.topics`)."""
    from dq_fk_ros.testing.topics import next_message as wait
    return wait(msg_type, topic, where, timeout_s, qos)


__all__ = ['assert_pose_close', 'next_message', 'pose_difference', 'wait_for_match',
           'wait_until']
