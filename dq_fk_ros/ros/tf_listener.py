"""
tf2_ros's ``TransformListener``: ``/tf`` and ``/tf_static`` into a :class:`Buffer`.

As tf2_ros's, by default both are subscriptions on the user's node, served by whatever
spins it (``rclpy.spin``, ``spin_once``, an executor of the user's); QoS as tf2_ros's
(``/tf`` depth 100; ``/tf_static`` depth 100, reliable, transient local: a listener joining
late gets every static transform). Messages are taken as bytes and read by the package's
own CDR reader (:class:`~dq_fk_ros.messages.cdr_tf.TfReader`): no Python message object per
transform.

With ``spin_thread=True`` (the listener spins the node in a thread of its own, as tf2_ros)
``/tf`` is taken by a faster input thread instead (``input_thread``): a hidden helper node
``_<node>_tf`` with one wait set, every message within ``INPUT_BATCH_S`` of the last taken in
one wake-up, not through the executor, whose wake-up per message cost more than the
transforms (the 1 kHz tiago_dual of benchmarks/bench_tf.py). Either way the buffer holds the
same transforms; threads are stopped by :meth:`TransformListener.unregister`, by
``rclpy.shutdown()`` and at exit, in any order.
"""

import threading
import time as _time

from dq_fk_ros.errors import CdrError
from dq_fk_ros.messages.cdr_tf import TfReader
from dq_fk_ros.transforms.buffer_core import COMPILED
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage

# tf2_ros's DynamicListenerQoS, StaticListenerQoS
DYNAMIC_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST)
STATIC_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)
LOG_EVERY_S = 10.0    # a listener's refused transforms: one line per this many seconds
AUTHORITY = 'default_authority'   # what tf2_ros's Python listener records
INPUT_BATCH_S = 0.002   # the listener's /tf thread: messages this close share a wake-up


class TransformListener:
    """
    tf2_ros's ``TransformListener``: ``/tf`` and ``/tf_static`` into a :class:`Buffer`.

    Messages are taken as bytes and read by the package's CDR reader; one that does not read
    is counted (``unreadable``) and logged at most once per ``LOG_EVERY_S``, as are refused
    transforms (the buffer's own one-line reasons).
    """

    def __init__(self, buffer, node, *, spin_thread: bool = False, qos=None,
                 static_qos=None, static_only: bool = False, input_thread=None):
        """
        Subscribe on ``node``; with ``spin_thread``, spin it in a thread of its own.

        :param input_thread: take ``/tf`` in a thread of its own (module doc); None (the
            default): where ``spin_thread`` is set, else a subscription on ``node`` as
            tf2_ros has it.
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
        input_thread = spin_thread if input_thread is None else input_thread
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
        """Store one message; ``counts['messages']`` goes up last, once it is stored whole."""
        try:
            layout = reader.layout(raw)
        except (CdrError, ValueError):
            self._log_unreadable()
            self.counts['messages'] += 1
            return
        if static or COMPILED is None or self.buffer.core.sclerp:
            self.counts['transforms'] += self.buffer.set_raw(
                TfReader.unpack(raw, layout), AUTHORITY, static)
        else:
            self.counts['transforms'] += self.buffer.append_raw(raw, layout, self._plans,
                                                                AUTHORITY)
        self.counts['refused'] = sum(self.buffer.core.refused.values())
        # last: a reader waiting on the count of messages finds their transforms and
        # refusals counted (a fresh-clone run read the refusals of all but the last message)
        self.counts['messages'] += 1

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


__all__ = ['AUTHORITY', 'DYNAMIC_QOS', 'STATIC_QOS', 'TransformListener']
