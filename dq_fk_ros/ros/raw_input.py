"""
A subscription served by a thread of its own: serialized messages, one wait set, no executor.

rclpy's ``SingleThreadedExecutor`` rebuilds its wait set in Python on every wake-up: at
1 kHz that alone takes about a third of a core (``benchmarks/bench_rclpy_floor.py``). A
thread that waits on one subscription with a wait set of its own and takes every queued
message costs about a sixth of that. The subscription lives on a hidden helper node
(``_<node>_input``), so the node's executor never sees it; timers, services and parameter
changes stay with the executor, and the owner serialises the two with a lock.
"""

import atexit
import ctypes
import threading
import time
from typing import Callable
import weakref

import rclpy
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

WAKE_S = 0.1  # the longest a stop request waits for the thread
OS_THREAD_NAME = b'dq_fk input'  # what top -H and /proc/<pid>/task/*/comm show
_PR_SET_NAME = 15
_RUNNING = weakref.WeakSet()   # the threads not closed yet: stopped before the interpreter ends


@atexit.register
def stop_all_threads() -> None:
    """
    Stop every input thread still running and wait for it (at exit, before finalisation).

    A thread left inside rcl's wait when the interpreter finalises is unwound through C++
    that may not throw: "terminate called without an active exception", exit 134. The
    ROS 2 tutorials' order (spin, ``rclpy.shutdown()``, end of script) did that; now every
    order ends cleanly (test_tf_listener.py's ``test_a_listener_ends_cleanly_*``).
    """
    for running in list(_RUNNING):
        running.stop()


def name_os_thread(name) -> bool:
    """
    Give the calling thread ``name`` (bytes, at most 15) where the OS shows thread names.

    Python's thread names stay inside Python; Linux's ``prctl(PR_SET_NAME)`` makes the
    thread findable in ``top -H`` and ``/proc``. Returns whether it was set.
    """
    try:
        libc = ctypes.CDLL(None)  # the process's own symbols: the C library's among them
        return libc.prctl(_PR_SET_NAME, ctypes.c_char_p(name[:15]), 0, 0, 0) == 0
    except (OSError, AttributeError, TypeError):  # not Linux: no prctl
        return False


def take_queued(subscription, callback, limit=None, with_info=False) -> int:
    """
    Hand every message already queued on a raw subscription to ``callback``, in order.

    At most ``limit`` (None: all); returns how many, when the queue is empty. ``with_info``:
    call ``callback(raw, info)`` with rclpy's message info dict
    (``publication_sequence_number``, timestamps). Raises what the subscription's handle
    raises once it is destroyed (a shutdown).
    """
    count = 0
    while limit is None or count < limit:
        with subscription.handle:
            taken = subscription.handle.take_message(subscription.msg_type, True)
        if taken is None:
            return count
        if with_info:
            callback(*taken)
        else:
            callback(taken[0])
        count += 1
    return count


def raw_publisher(publisher) -> Callable[[bytes], None]:
    """
    Return a function that publishes serialized messages (``bytes``) on ``publisher``.

    rclpy's ``Publisher.publish`` checks the message type and guards the handle against a
    concurrent destruction on every call (0.8 of its 1.6 us); the function returned calls
    the handle's ``publish_raw`` directly where this rclpy has it, else ``publish``. The
    caller must make sure the publisher is not destroyed meanwhile (the node publishes and
    replaces its publishers under one lock).
    """
    publish_raw = getattr(publisher.handle, 'publish_raw', None)
    return publish_raw if callable(publish_raw) else publisher.publish


class RawSubscriptionThread:
    """
    Call ``callback(raw_bytes, info)`` for every message of one topic, from its own thread.

    ``info`` is rclpy's message info dict (``publication_sequence_number``, timestamps).

    :param owner: the node it serves: its context, and its name for the hidden helper node.
    :param topic: a fully resolved topic name (the owner's remappings already applied).
    :param on_error: called with the exception when ``callback`` raises one; the thread
        counts it (:attr:`errors`) and goes on taking messages.
    :param batch_s: after handling what woke it, the thread looks for more messages only
        this much later (seconds; 0: at once), and again every ``batch_s`` while each look
        finds some; a look that finds none returns it to waiting. A wake-up costs more than
        the work of a message, and a CPU back from idle runs slow for a while: above
        ``1 / batch_s`` messages a second one wake-up serves several, each still handed over
        in order. Adds at most ``batch_s`` of latency; messages further apart than that are
        taken as they come.
    """

    def __init__(self, owner, msg_type, topic, qos, callback, batch_s=0.0, on_error=None,
                 role='input'):
        """Create the helper node (``_<owner>_<role>``) and its raw subscription; start."""
        self._context = owner.context
        self._node = rclpy.create_node(f'_{owner.get_name()}_{role}', context=self._context,
                                       start_parameter_services=False, enable_rosout=False,
                                       use_global_arguments=False)
        self.subscription = self._node.create_subscription(
            msg_type, topic, lambda _: None, qos, raw=True)
        self._callback = callback
        self._on_error = on_error
        self.errors = 0
        self._batch_s = batch_s
        self._stop = False
        self._thread = threading.Thread(target=self._run, name=f'{owner.get_name()} input',
                                        daemon=True)
        self._thread.start()
        _RUNNING.add(self)

    def stop(self) -> None:
        """Stop the thread and wait for it (the helper node stays: :meth:`close`)."""
        self._stop = True
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=5 * WAKE_S + 1.0)
        _RUNNING.discard(self)

    def _call(self, raw, info):
        """Hand one message to the callback; an exception is counted and reported, not fatal."""
        try:
            self._callback(raw, info)
        except Exception as exc:
            self.errors += 1
            if self._on_error is not None:
                try:
                    self._on_error(exc)
                except Exception:  # a report that fails must not stop the thread either
                    pass

    def _run(self):
        sub, context, batch_s = self.subscription, self._context, self._batch_s
        name_os_thread(OS_THREAD_NAME)
        try:
            wait_set = _rclpy.WaitSet(1, 0, 0, 0, 0, 0, context.handle)
            while not self._stop and context.ok():
                with sub.handle, context.handle:
                    wait_set.clear_entities()
                    wait_set.add_subscription(sub.handle)
                    wait_set.wait(int(WAKE_S * 1e9))
                taken = take_queued(sub, self._call, with_info=True)
                # while messages keep coming, look every batch_s without the wait set (its
                # wake-up costs more than a look): back to waiting once a look finds none
                while taken and batch_s and not self._stop:
                    time.sleep(batch_s)
                    taken = take_queued(sub, self._call, with_info=True)
        except Exception:  # waiting or taking failed: shut down or destroyed under us
            return

    def close(self) -> None:
        """Stop the thread and destroy the helper node."""
        self.stop()
        self._node.destroy_node()
