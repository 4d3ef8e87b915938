"""``dq_fk_bag play``: publish a bag's JointState messages with their recorded timing."""

import time

from dq_fk_ros.bag.progress import Progress
from dq_fk_ros.bag.reading import BagError, joint_state_connections, open_reader
from dq_fk_ros.ros.executables import MATCH_SETTLE_S

ACK_TIMEOUT_S = 5.0  # play: longest wait for reliable subscribers to acknowledge the end


def play_bag(path, topic=None, rate=1.0, loop=False, start_s=0.0, duration_s=None,
             clock=False, output_topic=None, progress=True, node=None, wait_for=0,
             wait_timeout_s=30.0):
    """
    Publish the bag's JointState messages with their recorded timing; return a summary.

    The summary dict: ``sent`` (messages published), ``note`` and ``error`` (lines about a
    bag read record by record, see :func:`open_reader`; ``error`` if it is damaged).

    Serialized messages are published as they are (no conversion). ``clock`` publishes
    ``/clock`` with the bag time before each message, for nodes with ``use_sim_time``.
    ``wait_for``: first wait until that many subscriptions are matched (messages sent
    before discovery completes are lost otherwise).
    """
    from dq_fk_ros.ros.conversions import ns_to_stamp
    import rclpy
    from rclpy.duration import Duration
    from rclpy.qos import QoSProfile
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState
    if rate <= 0:
        raise BagError(f'--rate must be positive, got {rate}')
    reader = open_reader(path)
    try:
        conns = joint_state_connections(reader, path, topic)
        own = node is None
        if own:
            rclpy.init(args=['--ros-args', '--log-level', 'warn'])
            node = rclpy.create_node('dq_fk_bag_play')
        pub = node.create_publisher(JointState, output_topic or conns[0].topic, 100)
        clock_pub = node.create_publisher(Clock, '/clock', QoSProfile(depth=10)) \
            if clock else None
        t_begin = reader.start_time + int(start_s * 1e9)
        t_end = None if duration_s is None else t_begin + int(duration_s * 1e9)
        total = sum(c.msgcount for c in conns)
        sent = 0
        deadline = time.monotonic() + wait_timeout_s
        while pub.get_subscription_count() < wait_for:
            if time.monotonic() > deadline:
                raise BagError(f'no {wait_for} subscribers on {pub.topic_name} within '
                               f'{wait_timeout_s:g} s')
            time.sleep(0.05)
        if wait_for:
            time.sleep(MATCH_SETTLE_S)  # the subscribers' side of the match may lag ours
        meter = Progress(total, 'dq_fk_bag play', enabled=progress)
        try:
            while True:
                wall0 = time.monotonic()
                for _, log_time, raw in reader.messages(connections=conns, start=t_begin,
                                                        stop=t_end):
                    delay = (log_time - t_begin) / 1e9 / rate - (time.monotonic() - wall0)
                    if delay > 0:
                        time.sleep(delay)
                    if clock_pub is not None:
                        clock_pub.publish(Clock(clock=ns_to_stamp(log_time)))
                    pub.publish(bytes(raw))
                    sent += 1
                    meter.update(sent)
                if not loop:
                    break
            # leaving at once would destroy the publishers before reliable subscribers
            # have the last messages (one was seen lost that way)
            for publisher in filter(None, (pub, clock_pub)):
                publisher.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S))
        finally:
            meter.update(sent, force=True)
            if own:
                node.destroy_node()
                rclpy.try_shutdown()
    finally:
        reader.close()
    return {'sent': sent, 'note': reader.note, 'error': reader.damage}
