"""
Worker processes that a Ctrl-C at the terminal does not reach, and stopping them ourselves.

A Ctrl-C goes to the terminal's whole process group: to the fleet's workers too, which
(still importing, say) would print a ``KeyboardInterrupt`` traceback each. Workers started
inside :func:`signals_blocked` inherit SIGINT blocked and never see it; the command that
does see it calls :func:`stop_children` (SIGTERM, then SIGKILL) before it exits.
"""

import contextlib
import multiprocessing
import signal
import time


@contextlib.contextmanager
def signals_blocked():
    """
    Block SIGINT in this thread while processes (or threads that start them) are started.

    A signal that comes meanwhile is delivered when the block ends.
    """
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def stop_children(timeout_s: float = 1.0) -> None:
    """
    Stop every child process multiprocessing started: SIGTERM, then SIGKILL after a while.

    A pool's workers and a Dask LocalCluster's (its nannies run in this process); not
    multiprocessing's resource tracker, which ends by itself once they all have.
    """
    children = multiprocessing.active_children()
    for child in children:
        child.terminate()
    deadline = time.monotonic() + timeout_s
    for child in children:
        child.join(max(0.0, deadline - time.monotonic()))
    for child in children:
        if child.is_alive():
            child.kill()
            child.join(0.5)


__all__ = ['signals_blocked', 'stop_children']
