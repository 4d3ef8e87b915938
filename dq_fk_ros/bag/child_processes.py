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
import sys
import threading
import time

# workers stopped at once leave semaphores the resource tracker then removes: it need not
# warn of each (a warning filter for the tracker, which takes the -W options of its parent)
QUIET_TRACKER = 'ignore:resource_tracker:UserWarning'


def prepare_children() -> None:
    """
    Start multiprocessing's resource tracker now, from this thread, quiet.

    Started later from a thread that blocks SIGINT, it would unblock SIGINT there (it blocks
    and then unblocks the signals around its own start), and every process that thread
    starts would see the terminal's Ctrl-C again.
    """
    from multiprocessing import resource_tracker
    if QUIET_TRACKER not in sys.warnoptions:  # (read by the processes started from now on)
        sys.warnoptions.append(QUIET_TRACKER)
    resource_tracker.ensure_running()


def run_with_sigint_blocked(make):
    """
    Return ``make()`` run in a thread that blocks SIGINT (its threads and processes too).

    This thread waits for it with SIGINT open: a Ctrl-C meanwhile raises here at once (the
    thread, a daemon, is left to the process's exit); what ``make`` raises is raised here.
    """
    prepare_children()
    box = {}

    def run():
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            box['value'] = make()
        except BaseException as exc:  # handed to the waiting thread
            box['error'] = exc
    thread = threading.Thread(target=run, name='dq_fk start workers', daemon=True)
    thread.start()
    while thread.is_alive():
        thread.join(0.05)
    if 'error' in box:
        raise box['error']
    return box['value']


@contextlib.contextmanager
def signals_blocked():
    """
    Block SIGINT in this thread while processes (or threads that start them) are started.

    A signal that comes meanwhile is delivered when the block ends (keep it short; else
    :func:`run_with_sigint_blocked`).
    """
    prepare_children()
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def stop_children(timeout_s: float = 1.0, at_once: bool = False) -> None:
    """
    Stop every child process multiprocessing started: SIGTERM, then SIGKILL after a while.

    A pool's workers and a Dask LocalCluster's (its nannies run in this process); not
    multiprocessing's resource tracker, which ends by itself once they all have.
    ``at_once``: SIGKILL straight away (a Dask worker takes its time over a SIGTERM).
    """
    children = multiprocessing.active_children()
    for child in children:
        child.kill() if at_once else child.terminate()
    deadline = time.monotonic() + timeout_s
    for child in children:
        child.join(max(0.0, deadline - time.monotonic()))
    for child in children:
        if child.is_alive():
            child.kill()
            child.join(0.5)


__all__ = ['prepare_children', 'run_with_sigint_blocked', 'signals_blocked', 'stop_children']
