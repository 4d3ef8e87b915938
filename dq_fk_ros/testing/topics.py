"""
Waits a test makes for an event, each with a deadline: never a sleep standing for one.

``next_message``: a context and a node of its own for each call (on the test's domain, as the
environment says), a subscription, and a spin until a message arrives (that ``where``
accepts) or the deadline passes. ``wait_for_match``: until a publisher and a subscription
have each matched the other (DDS matches the two sides apart: a message sent when only the
publisher has matched is lost to a volatile subscription). ``wait_until``: a predicate polled.
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


def wait_until(predicate, timeout_s: float = 10.0, every_s: float = 0.01) -> object:
    """Poll ``predicate()`` every ``every_s`` until true or ``timeout_s``; return its value."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value or time.monotonic() >= deadline:
            return value
        time.sleep(every_s)


def wait_for_match(publisher=None, subscription=None, count: int = 1,
                   timeout_s: float = 10.0) -> None:
    """
    Wait until ``publisher`` has ``count`` matched subscriptions and ``subscription`` as many.

    :param publisher: an rclpy publisher (``get_subscription_count``), or None.
    :param subscription: an rclpy subscription (``get_publisher_count``), or None.
    :raises AssertionError: not matched within ``timeout_s`` (which side, how many it has).
    """
    sides = [(name, getter) for name, getter in (
        ('publisher', publisher and publisher.get_subscription_count),
        ('subscription', subscription and subscription.get_publisher_count)) if getter]
    if not wait_until(lambda: all(getter() >= count for _, getter in sides), timeout_s):
        short = ', '.join(f'{name} matched {getter()}' for name, getter in sides
                          if getter() < count)
        raise AssertionError(f'not matched within {timeout_s:g} s (asked {count}): {short}')


__all__ = ['next_message', 'wait_for_match', 'wait_until']
