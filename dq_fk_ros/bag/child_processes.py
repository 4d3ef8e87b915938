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
from typing import Iterator

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


def run_with_sigint_blocked(make) -> object:
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
def signals_blocked() -> Iterator[None]:
    """
    Block SIGINT in this thread, and hold SIGINT and SIGTERM back, while it starts processes.

    The processes (and threads) started meanwhile inherit SIGINT blocked. A SIGINT or SIGTERM
    that comes meanwhile takes effect when the block ends (keep it short; else
    :func:`run_with_sigint_blocked`): in the main thread its Python handler is held back too
    (another thread may take the signal, and Python runs handlers in the main thread even
    where it is blocked), so none stops this thread half-way through handing a spawned
    worker its start-up data (the worker, left reading a closed pipe, would print an
    ``EOFError`` traceback, and it is not yet a child :func:`stop_children` knows).
    """
    prepare_children()
    caught = []
    held = {}
    if threading.current_thread() is threading.main_thread():
        for signum in (signal.SIGINT, signal.SIGTERM):
            handler = signal.getsignal(signum)
            if callable(handler):  # (not SIG_DFL, SIG_IGN, nor one set outside Python)
                held[signum] = handler
                signal.signal(signum, lambda number, frame: caught.append(number))
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)
        for signum, handler in held.items():
            signal.signal(signum, handler)
        if caught:
            signal.raise_signal(caught[0])


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
