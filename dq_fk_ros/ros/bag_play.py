"""``dq_fk_bag play``: publish a bag's JointState messages with their recorded timing."""

from dataclasses import dataclass, replace
import math
import time

from dq_fk_ros.bag.progress import Progress
from dq_fk_ros.errors import BagError, printable_line
from dq_fk_ros.ros.executables import MATCH_SETTLE_S
from dq_fk_ros.storage.reading import joint_state_connections, open_reader

ACK_TIMEOUT_S = 5.0  # play: longest wait for reliable subscribers to acknowledge the end


@dataclass(frozen=True)
class PlayOptions:
    """
    How :func:`play_bag` plays (the ``dq_fk_bag play`` options).

    ``rate``: speed factor; ``start_s``, ``duration_s``: the part played (seconds);
    ``clock``: publish ``/clock``; ``output_topic``: another topic than the bag's;
    ``wait_for``: subscriptions to wait for (at most ``wait_timeout_s``) before the first.
    """

    topic: str = None
    rate: float = 1.0
    loop: bool = False
    start_s: float = 0.0
    duration_s: float = None
    clock: bool = False
    output_topic: str = None
    progress: bool = True
    wait_for: int = 0
    wait_timeout_s: float = 30.0


@dataclass
class PlaySummary:
    """
    What :func:`play_bag` did: ``sent`` messages published; ``note``, ``error``: one line each.

    ``note`` and ``error`` say how the bag was read (record by record, see
    :func:`open_reader`); ``error`` if it is damaged; else None.
    """

    sent: int = 0
    note: str = None
    error: str = None


def play_bag(path, options=None, node=None, **changes) -> PlaySummary:
    """
    Publish the bag's JointState messages with their recorded timing; a :class:`PlaySummary`.

    :param options: a :class:`PlayOptions` (default: its defaults); ``changes`` are fields of
        it given by name. ``node``: publish from this rclpy node (default: one of its own).

    Serialized messages are published as they are (no conversion). ``clock`` publishes
    ``/clock`` with the bag time before each message, for nodes with ``use_sim_time``.
    ``wait_for``: first wait until that many subscriptions are matched (messages sent
    before discovery completes are lost otherwise).
    """
    from dq_fk_ros.ros.conversions import ns_to_stamp
    import rclpy
    from rclpy.duration import Duration
    from rclpy.exceptions import NameValidationException
    from rclpy.expand_topic_name import expand_topic_name
    from rclpy.validate_full_topic_name import validate_full_topic_name
    from rclpy.validate_topic_name import validate_topic_name
    from rclpy.qos import QoSProfile
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState
    o = replace(options or PlayOptions(), **changes)
    topic, rate, loop, start_s, duration_s = o.topic, o.rate, o.loop, o.start_s, o.duration_s
    clock, output_topic, progress = o.clock, o.output_topic, o.progress
    wait_for, wait_timeout_s = o.wait_for, o.wait_timeout_s
    if not rate > 0 or not math.isfinite(rate):
        raise BagError(f'--rate must be a positive number, got {rate}')
    if not 0 <= start_s < math.inf:
        raise BagError(f'--start must be 0 or more seconds, got {start_s}')
    if duration_s is not None and not 0 < duration_s < math.inf:
        raise BagError(f'--duration must be a positive number of seconds, got {duration_s}')
    if output_topic:
        try:   # (as the publisher will name it: a long name fails only once expanded)
            validate_topic_name(output_topic)
            validate_full_topic_name(expand_topic_name(output_topic, 'dq_fk_bag_play', '/'))
        except NameValidationException:
            raise BagError(f'--output-topic {printable_line(output_topic, 80)!r}: not a ROS '
                           'topic name (letters, digits, _ and /, at most 255 characters)') \
                from None
    reader = open_reader(path)
    try:
        conns = joint_state_connections(reader, path, topic)
        length_s = (reader.end_time - reader.start_time) / 1e9
        if start_s > length_s:
            raise BagError(f'--start {start_s:g} s is after the end of {path} '
                           f'({length_s:.3f} s long)')
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
        sent, stopped = 0, None
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
                stream = _tolerant(reader, conns, t_begin, t_end)
                for log_time, raw in stream:
                    delay = (log_time - t_begin) / 1e9 / rate - (time.monotonic() - wall0)
                    if delay > 0:
                        time.sleep(delay)
                    if clock_pub is not None:
                        clock_pub.publish(Clock(clock=ns_to_stamp(log_time)))
                    pub.publish(bytes(raw))
                    sent += 1
                    meter.update(sent)
                reader = stream.reader  # the fallback reader, if the first one stopped
                stopped = stopped or stream.stopped
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
    return PlaySummary(sent, reader.note, reader.damage or stopped)


class _tolerant:
    """
    Iterate ``(log_time, raw)`` of a reader, going on past a damaged chunk.

    If the reader fails inside a damaged chunk, reading goes on with its record-by-record
    fallback, after the last message already given.
    """

    def __init__(self, reader, conns, start, stop):
        self.reader, self.conns, self.start, self.stop = reader, conns, start, stop
        self.stopped = None  # one line, if reading stopped in damage with no fallback

    def __iter__(self):
        last, at_last = None, 0  # the last log time given, and how many had it
        try:
            for _, log_time, raw in self.reader.messages(connections=self.conns,
                                                         start=self.start, stop=self.stop):
                at_last = at_last + 1 if log_time == last else 1
                last = log_time
                yield log_time, raw
            return
        except Exception:
            retry = self.reader.fallback()
            if retry is None:
                self.stopped = 'reading stopped in a damaged part'
                return
        self.reader.close()
        self.reader = retry
        conns = [c for c in retry.connections if c.topic in {k.topic for k in self.conns}]
        self.conns = conns
        for _, log_time, raw in retry.messages(connections=conns, start=self.start,
                                               stop=self.stop):
            if last is not None and log_time < last:
                continue  # given before the first reader stopped
            if log_time == last and at_last > 0:
                at_last -= 1
                continue
            yield log_time, raw
