"""
tf2_ros's Python API over :class:`~dq_fk_ros.transforms.buffer_core.BufferCore`: no tf2 needed.

``Buffer``, ``TransformListener``, ``TransformBroadcaster`` and
``StaticTransformBroadcaster`` take and give what tf2_ros's do (rclpy ``Time`` and
``Duration``, ``geometry_msgs/TransformStamped``), so code written for tf2_ros runs after
its import becomes ``from dq_fk_ros import tf as tf2_ros``. The rules of a lookup are tf2's
(:mod:`dq_fk_ros.transforms.buffer_core`); times are integer nanoseconds inside.

The listener takes ``/tf`` and ``/tf_static`` as serialized bytes and reads them with the
package's own CDR reader (:class:`~dq_fk_ros.messages.cdr_tf.TfReader`): no Python message
object per transform. QoS as tf2_ros's: ``/tf`` depth 100; ``/tf_static`` depth 100,
reliable, transient local (a listener joining late gets every static transform).

Not here (tf2_ros has them): ``Buffer.transform`` (tf2_geometry_msgs's registrations), the
``tf2_frames`` service, ``lookup_transform_async`` and ``wait_for_transform_async``.
"""

import logging
import struct
import threading
import time as _time
from typing import TYPE_CHECKING

from builtin_interfaces.msg import Time as TimeMsg
from dq_fk_ros.errors import CdrError
from dq_fk_ros.messages.cdr_tf import TfReader
from dq_fk_ros.transforms.buffer_core import (BufferCore, COMPILED, DEFAULT_CACHE_TIME_NS,
                                              MAX_FRAME_ID, MAX_FRAMES, strip_slash)
from dq_fk_ros.transforms.exceptions import (ConnectivityException, ExtrapolationException,
                                             InvalidArgumentException, LookupException,
                                             TimeoutException, TransformException)
from geometry_msgs.msg import TransformStamped
import numpy as np
from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from tf2_msgs.msg import TFMessage

if TYPE_CHECKING:
    from numpy import ndarray

# tf2_ros's DynamicListenerQoS, StaticListenerQoS and the broadcasters' QoS
DYNAMIC_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST)
STATIC_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)
STATIC_BROADCASTER_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                                    reliability=ReliabilityPolicy.RELIABLE,
                                    durability=DurabilityPolicy.TRANSIENT_LOCAL)
LOG_EVERY_S = 10.0    # a listener's refused transforms: one line per this many seconds
_STAMP, _POSE7 = struct.Struct('<iI'), struct.Struct('<7d')
AUTHORITY = 'default_authority'   # what tf2_ros's Python listener records
INPUT_BATCH_S = 0.002   # the listener's /tf thread: messages this close share a wake-up
SLICE = 256             # transforms of one message stored under one hold of the lock
MAX_PLANS = 64          # layouts whose frame ids a listener remembers (as its reader's)


def time_ns(value) -> int:
    """Return ``value`` (rclpy ``Time``, a ``builtin_interfaces/Time``, or int ns) in ns."""
    if isinstance(value, Time):
        return value.nanoseconds
    if isinstance(value, TimeMsg):
        return value.sec * 1_000_000_000 + value.nanosec
    if type(value) is int:
        return value
    raise TypeError(f'a time is an rclpy Time, a builtin_interfaces Time or int ns, not '
                    f'{type(value).__name__}')


def duration_ns(value) -> int:
    """Return ``value`` (rclpy ``Duration`` or int ns) in ns."""
    if isinstance(value, Duration):
        return value.nanoseconds
    if type(value) is int:
        return value
    raise TypeError(f'a duration is an rclpy Duration or int ns, not {type(value).__name__}')


def to_message(target, source, pose, stamp_ns) -> TransformStamped:
    """
    Return a ``TransformStamped`` of ``pose`` (x y z qx qy qz qw) at ``stamp_ns``.

    The fields are set on the default message's own parts (about 1.5 us over the empty
    message's construction; its constructor with keyword arguments costs twice that).
    """
    msg = TransformStamped()
    header, transform = msg.header, msg.transform
    header.frame_id, msg.child_frame_id = target, source
    stamp = header.stamp
    stamp.sec, stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    t, r = transform.translation, transform.rotation
    t.x, t.y, t.z = pose[0], pose[1], pose[2]
    r.x, r.y, r.z, r.w = pose[3], pose[4], pose[5], pose[6]
    return msg


class Buffer:
    """
    tf2_ros's ``Buffer``: transforms in, lookups out, by tf2's rules (module doc).

    :param cache_time: how long each edge keeps its samples (``Duration``; tf2's 10 s).
    :param node: accepted as tf2_ros's; no ``tf2_frames`` service is made.
    :param interpolation: ``'slerp'`` (tf2's) or ``'sclerp'`` (screw motion, not tf2's).
    :param max_frames: frame names held at most; transforms naming more are refused.

    ``core`` is the :class:`~dq_fk_ros.transforms.buffer_core.BufferCore`; ``lock`` guards it
    (hold it to read ``core`` while a listener writes).
    """

    def __init__(self, cache_time=None, node=None, interpolation='slerp',
                 max_frames=MAX_FRAMES, log=None):
        """Start empty."""
        cache_ns = DEFAULT_CACHE_TIME_NS if cache_time is None else duration_ns(cache_time)
        self.lock = threading.Lock()
        self._changed = threading.Condition(self.lock)
        self.core = BufferCore(cache_ns, interpolation, max_frames,
                               log or logging.getLogger('dq_fk_ros.tf').warning)
        self.node = node

    # -- in -------------------------------------------------------------------------------
    def set_transform(self, transform: TransformStamped, authority: str) -> bool:
        """Store a transform (as tf2_ros's; False: refused, one log line)."""
        return self._set(transform, authority, False)

    def set_transform_static(self, transform: TransformStamped, authority: str) -> bool:
        """Store a static transform, valid at every time."""
        return self._set(transform, authority, True)

    def _set(self, transform, authority, static):
        t, r = transform.transform.translation, transform.transform.rotation
        stamp = transform.header.stamp
        with self._changed:
            done = self.core.set_transform(
                transform.header.frame_id, transform.child_frame_id,
                stamp.sec * 1_000_000_000 + stamp.nanosec, (t.x, t.y, t.z, r.x, r.y, r.z, r.w),
                authority, static)
            self._changed.notify_all()
        return done

    def set_raw(self, transforms, authority: str, static: bool = False) -> int:
        """Store ``[(parent, child, stamp_ns, pose)]`` (the listener's); return how many taken."""
        taken = 0
        for lo in range(0, len(transforms), SLICE):   # lookups go between slices
            with self._changed:
                for parent, child, stamp, pose in transforms[lo:lo + SLICE]:
                    taken += self.core.set_transform(parent, child, stamp, pose, authority,
                                                     static)
                self._changed.notify_all()
            _time.sleep(0)   # hand over: a lookup waiting on the lock takes it (not fair)
        return taken

    def append_raw(self, raw: bytes, layout, plans: dict, authority: str) -> int:
        """
        Store a serialized ``/tf`` message of a known ``layout``; return how many were taken.

        Fast path: ``_tf.append_many`` appends each transform newer than its edge's newest
        (the common case) in C; every other one (a new frame, an older or equal stamp, a
        refusal) goes through ``BufferCore.set_transform``, the reference
        (``test_tf_listener.py``'s ``test_the_listener_stores_what_set_transform_stores``).
        ``plans`` keeps each layout's frame ids and offsets (ids never change), at most
        ``MAX_PLANS``. The lock is taken for ``SLICE`` transforms at a time: a lookup waits
        for one slice of a peer's message at most, never for the whole of it.
        """
        core = self.core
        with self._changed:
            plan = plans.get(id(layout))
            if plan is None or plan[0] is not layout or plan[2]:
                plan = plans[id(layout)] = self._plan(layout)
                if len(plans) > MAX_PLANS:
                    plans.pop(next(iter(plans)))
        rows, taken = plan[1], 0
        stamp, pose = _STAMP.unpack_from, _POSE7.unpack_from
        for lo in range(0, len(rows), SLICE):
            with self._changed:
                part = rows[lo:lo + SLICE]
                left = COMPILED.append_many(core.caches, part, raw, core.cache_time_ns)
                taken += len(part) - len(left)
                skipped = set(left)
                for i, child in enumerate(part[:, 0].tolist()):
                    if child and i not in skipped:
                        core.authority[child] = authority
                for i in left:
                    parent, child = layout.edges[lo + i]
                    sec, nanosec = stamp(raw, layout.stamps[lo + i])
                    taken += core.set_transform(parent, child, sec * 1_000_000_000 + nanosec,
                                                pose(raw, layout.values[lo + i]), authority)
                self._changed.notify_all()
            _time.sleep(0)   # hand over: a lookup waiting on the lock takes it (not fair)
        return taken

    def _plan(self, layout):
        """Return ``(layout, rows (child id, parent id, stamp at, values at), incomplete)``."""
        core = self.core
        rows, incomplete = [], False
        for (parent, child), at, value_at in zip(layout.edges, layout.stamps, layout.values):
            p, c = strip_slash(parent), strip_slash(child)
            named = p and c and p != c and max(len(p), len(c)) <= MAX_FRAME_ID
            good = named and core.ids.get(c) and core.ids.get(p)
            incomplete |= bool(named and not good)   # frames not seen yet
            rows.append((core.ids[c] if good else 0, core.ids[p] if good else 0, at, value_at))
        return (layout, np.array(rows, np.int64).reshape(-1, 4),
                incomplete and len(core.names) <= core.max_frames)

    def wait_for_data(self, timeout_s: float) -> None:
        """Return when transforms were stored, or after ``timeout_s`` (not tf2_ros's)."""
        with self._changed:
            self._changed.wait(timeout_s)

    def clear(self) -> None:
        """Forget every sample."""
        with self.lock:
            self.core.clear()

    # -- out ------------------------------------------------------------------------------
    def lookup_transform(self, target_frame: str, source_frame: str, time,
                         timeout=None) -> TransformStamped:
        """
        Return ``source_frame``'s pose in ``target_frame`` at ``time`` (0: the latest common).

        With a ``timeout``, wait that long for the data to arrive (on a listener). Raises
        tf2's exceptions (:class:`LookupException`, :class:`ConnectivityException`,
        :class:`ExtrapolationException`, :class:`InvalidArgumentException`).
        """
        stamp = time_ns(time)
        if timeout is not None and duration_ns(timeout) > 0:
            self._wait(lambda: self.core.can_transform(target_frame, source_frame, stamp),
                       timeout)
        with self.lock:
            pose, used = self.core.lookup(target_frame, source_frame, stamp)
        return to_message(target_frame, source_frame, pose, used)

    def lookup_transform_full(self, target_frame: str, target_time, source_frame: str,
                              source_time, fixed_frame: str, timeout=None) -> TransformStamped:
        """Return ``source_frame`` at ``source_time`` in ``target_frame`` at ``target_time``."""
        target_ns, source_ns = time_ns(target_time), time_ns(source_time)
        self._wait(lambda: self.core.can_transform_full(target_frame, target_ns, source_frame,
                                                        source_ns, fixed_frame), timeout)
        with self.lock:
            pose, used = self.core.lookup_full(target_frame, target_ns, source_frame,
                                               source_ns, fixed_frame)
        return to_message(target_frame, source_frame, pose, used)

    def can_transform(self, target_frame: str, source_frame: str, time, timeout=None,
                      return_debug_tuple: bool = False) -> 'bool | tuple':
        """Return whether the lookup would answer (waiting up to ``timeout``)."""
        stamp = time_ns(time)
        answer = self._wait(lambda: self.core.can_transform(target_frame, source_frame,
                                                            stamp), timeout)
        return answer if return_debug_tuple else answer[0]

    def can_transform_full(self, target_frame: str, target_time, source_frame: str,
                           source_time, fixed_frame: str, timeout=None,
                           return_debug_tuple: bool = False) -> 'bool | tuple':
        """Return whether :meth:`lookup_transform_full` would answer."""
        target_ns, source_ns = time_ns(target_time), time_ns(source_time)
        answer = self._wait(lambda: self.core.can_transform_full(
            target_frame, target_ns, source_frame, source_ns, fixed_frame), timeout)
        return answer if return_debug_tuple else answer[0]

    def _wait(self, check, timeout):
        """Return ``check()`` (``(ok, why)``) under the lock, again as data come, to timeout."""
        wait_ns = 0 if timeout is None else duration_ns(timeout)
        deadline = _time.monotonic() + wait_ns / 1e9
        with self._changed:
            while True:
                answer = check()
                left = deadline - _time.monotonic()
                if answer[0] or left <= 0:
                    return answer
                self._changed.wait(min(left, 0.1))

    def lookup_poses(self, target_frame: str, source_frame: str, stamps_ns) -> 'ndarray':
        """
        Return ``source_frame``'s pose in ``target_frame`` at each stamp: (N, 7) rows.

        Rows x y z qx qy qz qw (m; quaternion x y z w).

        A NaN row where TF cannot answer (``lookup_transform`` would raise); what
        ``dq_fk_bag tf`` writes (:func:`dq_fk_ros.transforms.batch.lookup_poses`).
        """
        from dq_fk_ros.transforms.batch import lookup_poses
        with self.lock:
            return lookup_poses(self.core, target_frame, source_frame, stamps_ns)

    def all_frames_as_yaml(self, current_time=None) -> str:
        """Return tf2's ``allFramesAsYAML``."""
        with self.lock:
            return self.core.all_frames_as_yaml(0 if current_time is None
                                                else time_ns(current_time))

    def all_frames_as_string(self) -> str:
        """Return tf2's ``allFramesAsString``."""
        with self.lock:
            return self.core.all_frames_as_string()


def buffer_from_bag(path, start=None, end=None, interpolation: str = 'slerp') -> Buffer:
    """
    Return a :class:`Buffer` holding a bag's ``/tf`` and ``/tf_static`` (every format).

    :param start: the first log time of ``/tf`` read (rclpy ``Time`` or int ns; None: the
        bag's start); ``end``: the first not read. ``/tf_static`` is read whole.
    :raises BagError: no TF in the bag, or more transforms than held (one line).
    Details: :func:`dq_fk_ros.bag.tf_bag.core_from_bag`; ``buffer.bag_summary`` says what
    was read and dropped.
    """
    from dq_fk_ros.bag.tf_bag import core_from_bag
    core, summary = core_from_bag(path, None if start is None else time_ns(start),
                                  None if end is None else time_ns(end),
                                  interpolation=interpolation)
    buffer = Buffer(interpolation=interpolation)
    core.log = buffer.core.log
    buffer.core = core
    buffer.bag_summary = summary
    return buffer


class TransformListener:
    """
    tf2_ros's ``TransformListener``: ``/tf`` and ``/tf_static`` into a :class:`Buffer`.

    Messages are taken as bytes and read by the package's CDR reader; one that does not read
    is counted (``unreadable``) and logged at most once per ``LOG_EVERY_S``, as are refused
    transforms (the buffer's own one-line reasons).
    """

    def __init__(self, buffer: Buffer, node, *, spin_thread: bool = False, qos=None,
                 static_qos=None, static_only: bool = False, input_thread: bool = True):
        """
        Subscribe on ``node``; with ``spin_thread``, spin it in a thread of its own.

        :param input_thread: take ``/tf`` in a thread of its own (a hidden helper node
            ``_<node>_tf`` and one wait set, as dq_fk_node takes joint states; every
            message within ``INPUT_BATCH_S`` of the last is taken in the same wake-up), not
            through the executor, whose wake-up per message cost more than the transforms;
            False: a subscription on ``node`` as tf2_ros has it.
        """
        from rclpy.callback_groups import ReentrantCallbackGroup
        self.buffer, self.node = buffer, node
        self.counts = {'messages': 0, 'transforms': 0, 'refused': 0, 'unreadable': 0}
        self._reader, self._static_reader = TfReader(), TfReader()
        self._plans = {}   # layout -> its transforms' ids and offsets (Buffer.append_raw)
        self._last_log = 0.0
        self._log_lock = threading.Lock()
        buffer.core.log = self._log
        group = ReentrantCallbackGroup()
        self.tf_sub = self.tf_thread = None
        if not static_only and input_thread:
            from dq_fk_ros.ros.raw_input import RawSubscriptionThread
            self.tf_thread = RawSubscriptionThread(
                node, TFMessage, '/tf', qos or DYNAMIC_QOS, lambda raw, _: self._on_tf(raw),
                batch_s=INPUT_BATCH_S, role='tf')
        elif not static_only:
            self.tf_sub = node.create_subscription(
                TFMessage, '/tf', self._on_tf, qos or DYNAMIC_QOS, callback_group=group,
                raw=True)
        self.tf_static_sub = node.create_subscription(
            TFMessage, '/tf_static', self._on_static, static_qos or STATIC_QOS,
            callback_group=group, raw=True)
        self.executor, self.dedicated_listener_thread = None, None
        if spin_thread:
            from rclpy.executors import SingleThreadedExecutor
            self.executor = SingleThreadedExecutor(context=node.context)

            def run():
                self.executor.add_node(node)
                try:
                    self.executor.spin()
                except Exception:   # the context shut down
                    pass
                finally:
                    self.executor.remove_node(node)
            self.dedicated_listener_thread = threading.Thread(target=run, daemon=True,
                                                              name='dq_fk tf listener')
            self.dedicated_listener_thread.start()

    def _log(self, line):
        """Log a line of the buffer's (already at most one a code every LOG_EVERY_S)."""
        self.node.get_logger().warning(line)

    def _log_unreadable(self):
        self.counts['unreadable'] += 1
        now = _time.monotonic()
        with self._log_lock:
            if now - self._last_log < LOG_EVERY_S:
                return
            self._last_log = now
        self.node.get_logger().warning(
            'a TFMessage that does not read as one (not CDR, truncated, or frame ids that are '
            f"not UTF-8) ({self.counts['unreadable']} so far)")

    def _on_tf(self, raw):
        self._take(raw, self._reader, False)

    def _on_static(self, raw):
        self._take(raw, self._static_reader, True)

    def _take(self, raw, reader, static):
        self.counts['messages'] += 1
        try:
            layout = reader.layout(raw)
        except (CdrError, ValueError):
            self._log_unreadable()
            return
        if static or COMPILED is None or self.buffer.core.sclerp:
            self.counts['transforms'] += self.buffer.set_raw(
                TfReader.unpack(raw, layout), AUTHORITY, static)
        else:
            self.counts['transforms'] += self.buffer.append_raw(raw, layout, self._plans,
                                                                AUTHORITY)
        self.counts['refused'] = sum(self.buffer.core.refused.values())

    def unregister(self) -> None:
        """Destroy the subscriptions (tf2_ros's ``unregister``)."""
        for sub in (self.tf_sub, self.tf_static_sub):
            if sub is not None:
                self.node.destroy_subscription(sub)
        if self.tf_thread is not None:
            self.tf_thread.close()
        self.tf_sub = self.tf_static_sub = self.tf_thread = None
        if self.executor is not None:
            self.executor.shutdown()
            self.dedicated_listener_thread.join(timeout=2.0)

    def __del__(self):
        """Nothing: :meth:`unregister` stops it (a finaliser may run after rclpy shut down)."""


class TransformBroadcaster:
    """tf2_ros's ``TransformBroadcaster``: ``send_transform`` publishes on ``/tf``."""

    def __init__(self, node, qos=None):
        """Create the ``/tf`` publisher on ``node`` (depth 100, as tf2_ros)."""
        self.pub_tf = node.create_publisher(TFMessage, '/tf', qos or DYNAMIC_QOS)

    def send_transform(self, transform) -> None:
        """Publish one ``TransformStamped`` or a list of them."""
        transforms = transform if isinstance(transform, (list, tuple)) else [transform]
        self.pub_tf.publish(TFMessage(transforms=list(transforms)))


class StaticTransformBroadcaster:
    """tf2_ros's ``StaticTransformBroadcaster``: every transform sent, latched on /tf_static."""

    def __init__(self, node, qos=None):
        """Create the latched ``/tf_static`` publisher (reliable, transient local, depth 1)."""
        self.pub_tf = node.create_publisher(TFMessage, '/tf_static',
                                            qos or STATIC_BROADCASTER_QOS)
        self._net = {}   # child frame -> its newest transform

    def send_transform(self, transform) -> None:
        """Add or replace transforms by child frame; publish all of them (as tf2_ros)."""
        transforms = transform if isinstance(transform, (list, tuple)) else [transform]
        for t in transforms:
            self._net[t.child_frame_id] = t
        self.pub_tf.publish(TFMessage(transforms=list(self._net.values())))


__all__ = ['Buffer', 'buffer_from_bag', 'ConnectivityException', 'ExtrapolationException',
           'InvalidArgumentException', 'LookupException', 'StaticTransformBroadcaster',
           'TimeoutException', 'TransformBroadcaster', 'TransformException',
           'TransformListener']
