"""
``next_message``: the next message on a topic that a test waits for, with a deadline.

A context and a node of its own for each call (on the test's domain, as the environment
says), a subscription, and a spin until a message arrives (that ``where`` accepts) or the
deadline passes: a wait for an event, never a sleep.
"""

import os
import time


def next_message(msg_type, topic: str, where=None, timeout_s: float = 10.0,
                 qos=10) -> object:
    """
    Return the first message on ``topic`` (of ``msg_type``) for which ``where(msg)`` holds.

    :param where: a predicate on the message (default: any message).
    :param qos: a depth or an rclpy ``QoSProfile`` (a latched topic needs its durability).
    :raises AssertionError: none within ``timeout_s`` (one line: how many came, none taken).
    """
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node(f'dq_fk_test_topic_{os.getpid()}_{id(context):x}',
                             context=context, enable_rosout=False,
                             start_parameter_services=False)
    executor = SingleThreadedExecutor(context=context)
    got, seen = [], [0]

    def take(msg):
        seen[0] += 1
        if not got and (where is None or where(msg)):
            got.append(msg)
    try:
        node.create_subscription(msg_type, topic, take, qos)
        executor.add_node(node)
        deadline = time.monotonic() + timeout_s
        while not got and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=min(0.1, max(0.0, deadline - time.monotonic())))
    finally:
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()
    if not got:
        raise AssertionError(f'no {msg_type.__name__} on {topic} within {timeout_s:g} s'
                             + (f' ({seen[0]} came, none as asked)' if seen[0] else ''))
    return got[0]


__all__ = ['next_message']
