"""
tf2_ros's ``Buffer`` over the array core: transforms in, lookups and ``transform`` out.

``Buffer`` is what tf2_ros's is: tf2_py's ``BufferCore``
(:class:`~dq_fk_ros.ros.tf_message_core.MessageBufferCore`) and tf2_ros's
``BufferInterface`` (:mod:`dq_fk_ros.ros.tf_registration`: ``transform``,
``transform_full``), with lookups that wait (``timeout``), the async forms
(``lookup_transform_async``, ``wait_for_transform_async`` and their ``_full``: rclpy
``Future`` s completed when the data arrive, as geometry2's ``tf2_ros_py/tf2_ros/buffer.py``),
the ``tf2_frames`` service on a ``node`` given, and the whole buffer cleared when the clock
jumps back by more than a second (a bag played again), as tf2_ros's. Times are rclpy
``Time``, ``builtin_interfaces/Time`` or int ns; integer ns inside. The rules of a lookup are
tf2's (:mod:`dq_fk_ros.transforms.buffer_core`).

What a listener stores comes in through :meth:`Buffer.set_raw` and :meth:`Buffer.append_raw`
(:mod:`dq_fk_ros.ros.tf_listener`), a slice of transforms under each hold of the lock.
"""

import logging
import struct
import threading
import time as _time
from typing import TYPE_CHECKING

from dq_fk_ros.ros.tf_message_core import (duration_ns, MessageBufferCore, time_ns,
                                           to_message)
from dq_fk_ros.ros.tf_registration import BufferInterface
from dq_fk_ros.transforms.buffer_core import COMPILED, MAX_FRAME_ID, MAX_FRAMES, strip_slash
from geometry_msgs.msg import TransformStamped
import numpy as np

if TYPE_CHECKING:
    from numpy import ndarray
    from rclpy.task import Future

_STAMP, _POSE7 = struct.Struct('<iI'), struct.Struct('<7d')
SLICE = 256             # transforms of one message stored under one hold of the lock
MAX_PLANS = 64          # layouts whose frame ids a listener remembers (as its reader's)
JUMP_BACK_S = 1.0       # tf2_ros's: a clock jumping back further clears the buffer


class Buffer(MessageBufferCore, BufferInterface):
    """
    tf2_ros's ``Buffer`` (module doc).

    :param cache_time: how long each edge keeps its samples (``Duration``; tf2's 10 s).
    :param node: where to offer the ``tf2_frames`` service (``tf2_msgs/srv/FrameGraph``:
        :meth:`all_frames_as_yaml`) and whose clock's jumps back clear the buffer (None: a
        system clock's, as tf2_ros).
    :param interpolation: ``'slerp'`` (tf2's) or ``'sclerp'`` (screw motion, not tf2's).
    :param max_frames: frame names held at most; transforms naming more are refused.

    ``core`` is the :class:`~dq_fk_ros.transforms.buffer_core.BufferCore`; ``lock`` guards it
    (hold it to read ``core`` while a listener writes).
    """

    def __init__(self, cache_time=None, node=None, interpolation='slerp',
                 max_frames=MAX_FRAMES, log=None):
        """Start empty."""
        MessageBufferCore.__init__(self, cache_time, interpolation, max_frames,
                                   log or logging.getLogger('dq_fk_ros.tf').warning)
        BufferInterface.__init__(self)
        self.node = node
        self._new_data_callbacks = []
        self._callbacks_lock = threading.RLock()
        self.srv = None
        if node is not None:
            from tf2_msgs.srv import FrameGraph
            self.srv = node.create_service(FrameGraph, 'tf2_frames', self._frames)
            self.clock = node.get_clock()
        else:
            from rclpy.clock import Clock
            self.clock = Clock()
        from rclpy.clock import JumpThreshold
        from rclpy.duration import Duration
        self.jump_handle = self.clock.create_jump_callback(
            JumpThreshold(min_forward=None, min_backward=Duration(seconds=-JUMP_BACK_S),
                          on_clock_change=True),
            post_callback=self.time_jump_callback)

    def _frames(self, request, response):
        response.frame_yaml = self.all_frames_as_yaml()
        return response

    def time_jump_callback(self, time_jump=None) -> None:
        """Clear the buffer: the clock jumped back (tf2_ros's, with its log line)."""
        logging.getLogger('tf2_buffer').warning('Detected jump back in time. Clearing tf '
                                                'buffer.')
        self.clear()

    # -- in -------------------------------------------------------------------------------
    def set_transform(self, transform: TransformStamped, authority: str) -> None:
        """Store a transform (tf2's refusals are counted in ``core.refused`` and logged)."""
        self._store(transform, authority, False)
        self._call_new_data_callbacks()

    def set_transform_static(self, transform: TransformStamped, authority: str) -> None:
        """Store a static transform, valid at every time."""
        self._store(transform, authority, True)
        self._call_new_data_callbacks()

    def _call_new_data_callbacks(self) -> None:
        """Let each waiting future check again (in the storing thread, as tf2_ros)."""
        if not self._new_data_callbacks:
            return
        with self._callbacks_lock:
            for callback in list(self._new_data_callbacks):
                callback()

    def _remove_callback(self, callback) -> None:
        with self._callbacks_lock:
            if callback in self._new_data_callbacks:
                self._new_data_callbacks.remove(callback)

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
        self._call_new_data_callbacks()
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
        self._call_new_data_callbacks()
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
        with self.lock:   # lookup_transform_core's, inline: the hot path
            pose, used = self.core.lookup(target_frame, source_frame, stamp)
        return to_message(target_frame, source_frame, pose, used)

    def lookup_transform_full(self, target_frame: str, target_time, source_frame: str,
                              source_time, fixed_frame: str, timeout=None) -> TransformStamped:
        """Return ``source_frame`` at ``source_time`` in ``target_frame`` at ``target_time``."""
        target_ns, source_ns = time_ns(target_time), time_ns(source_time)
        self._wait(lambda: self.core.can_transform_full(target_frame, target_ns, source_frame,
                                                        source_ns, fixed_frame), timeout)
        return self.lookup_transform_full_core(target_frame, target_ns, source_frame,
                                               source_ns, fixed_frame)

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

    # -- async ----------------------------------------------------------------------------
    async def lookup_transform_async(self, target_frame: str, source_frame: str, time):
        """Return the transform once it can be given (a coroutine, as tf2_ros's)."""
        await self.wait_for_transform_async(target_frame, source_frame, time)
        return self.lookup_transform_core(target_frame, source_frame, time)

    async def lookup_transform_full_async(self, target_frame: str, target_time,
                                          source_frame: str, source_time, fixed_frame: str):
        """Return the transform via ``fixed_frame`` once it can be given (a coroutine)."""
        await self.wait_for_transform_full_async(target_frame, target_time, source_frame,
                                                 source_time, fixed_frame)
        return self.lookup_transform_full_core(target_frame, target_time, source_frame,
                                               source_time, fixed_frame)

    def wait_for_transform_async(self, target_frame: str, source_frame: str,
                                 time) -> 'Future':
        """Return an rclpy ``Future`` done with the transform when it can be given."""
        return self._future(
            lambda: self.can_transform_core(target_frame, source_frame, time)[0],
            lambda: self.lookup_transform_core(target_frame, source_frame, time))

    def wait_for_transform_full_async(self, target_frame: str, target_time,
                                      source_frame: str, source_time,
                                      fixed_frame: str) -> 'Future':
        """Return an rclpy ``Future`` done with the transform via ``fixed_frame``."""
        args = (target_frame, target_time, source_frame, source_time, fixed_frame)
        return self._future(lambda: self.can_transform_full_core(*args)[0],
                            lambda: self.lookup_transform_full_core(*args))

    def _future(self, ready, lookup):
        """Return a ``Future`` set by the first store after which ``ready()`` (tf2_ros's rule)."""
        from rclpy.task import Future
        future = Future()
        if ready():
            future.set_result(lookup())
            return future

        def on_new_data():
            if future.done():
                return
            try:
                if ready():
                    future.set_result(lookup())
            except Exception as error:   # a lookup that raised after all: the future's
                future.set_exception(error)

        with self._callbacks_lock:
            self._new_data_callbacks.append(on_new_data)
        future.add_done_callback(lambda _: self._remove_callback(on_new_data))
        return future


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


__all__ = ['Buffer', 'buffer_from_bag', 'duration_ns', 'time_ns', 'to_message']
