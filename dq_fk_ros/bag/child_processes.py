"""
Worker processes that a Ctrl-C at the terminal does not reach, and stopping them ourselves.

A Ctrl-C goes to the terminal's whole process group: to the fleet's workers too, which
(still importing, say) would print a ``KeyboardInterrupt`` traceback each. Workers started
inside :func:`signals_blocked` inherit SIGINT blocked and never see it; the command that
does see it calls :func:`stop_children` (SIGTERM, then SIGKILL) before it exits.

A worker is started in two steps: its process, then its start-up data written to it through
a pipe. A process that exits between the two leaves the worker reading a closed pipe, and
it prints an ``EOFError`` traceback; Dask starts its workers from threads of its own, which
a signal does not stop. So every spawned start runs under one lock (:func:`prepare_children`
installs it), and :func:`stop_children` takes that lock first: no worker is half-started
when it looks, and it stops those whose start has not yet been counted as a child.
"""

import contextlib
import multiprocessing
import os
import signal
import sys
import threading
import time
from typing import Iterator
import weakref

# workers stopped at once leave semaphores the resource tracker then removes: it need not
# warn of each (a warning filter for the tracker, which takes the -W options of its parent)
QUIET_TRACKER = 'ignore:resource_tracker:UserWarning'

_START_LOCK = threading.RLock()  # held while a spawned worker starts (process and data)
_GUARD_LOCK = threading.Lock()  # one installation of the guard, whichever thread asks
_STARTED = weakref.WeakSet()  # the spawned workers' Popen objects (children not yet counted)
_NO_MORE = []  # set by stop_children(for_good=True): no worker starts after it
_LOCK_WAIT_S = 5.0  # longest wait for a start under way (one takes milliseconds)


def prepare_children() -> None:
    """
    Start multiprocessing's resource tracker now, from this thread, quiet; guard starts.

    Started later from a thread that blocks SIGINT, it would unblock SIGINT there (it blocks
    and then unblocks the signals around its own start), and every process that thread
    starts would see the terminal's Ctrl-C again. The guard: see the module's docstring.
    """
    from multiprocessing import resource_tracker
    if QUIET_TRACKER not in sys.warnoptions:  # (read by the processes started from now on)
        sys.warnoptions.append(QUIET_TRACKER)
    resource_tracker.ensure_running()
    _guard_spawned_starts()


def _guard_spawned_starts() -> None:
    """
    Run every start of a 'spawn' worker under :data:`_START_LOCK` (once per process).

    multiprocessing has no hook for it: this wraps ``popen_spawn_posix.Popen._launch``, which
    starts the process and writes its data (test/integration/test_fleet.py's
    ``test_a_signal_while_a_worker_starts_leaves_no_traceback`` holds it to that).
    """
    from multiprocessing import popen_spawn_posix
    with _GUARD_LOCK:
        launch = popen_spawn_posix.Popen._launch
        if not getattr(launch, 'dq_fk_guarded', False):
            popen_spawn_posix.Popen._launch = _guarded(launch)


def _guarded(launch):
    """
    Return ``launch`` run under :data:`_START_LOCK`, refused after a for-good stop.

    Refused: the main thread gets a ``RuntimeError`` saying so; another thread (Dask's,
    starting a worker while the command exits) waits, quietly, for the process to exit.
    """

    def guarded_launch(popen, process_obj):
        with _START_LOCK:
            if not _NO_MORE:
                launch(popen, process_obj)
                _STARTED.add(popen)
                return
        if threading.current_thread() is threading.main_thread():
            raise RuntimeError('no worker process can start: an interrupted run stopped them '
                               'for good in this Python process; start a new one')
        threading.Event().wait()
    guarded_launch.dq_fk_guarded = True
    return guarded_launch


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


def stop_children(timeout_s: float = 1.0, at_once: bool = False,
                  for_good: bool = False) -> None:
    """
    Stop every child process multiprocessing started: SIGTERM, then SIGKILL after a while.

    A pool's workers and a Dask LocalCluster's (its nannies run in this process), also one
    whose start another thread has just finished; not multiprocessing's resource tracker,
    which ends by itself once they all have. It waits for a start under way to finish.
    ``at_once``: SIGKILL straight away (a Dask worker takes its time over a SIGTERM).
    ``for_good``: no worker starts after this (the main thread trying is told so in a
    ``RuntimeError``, another thread waits for ever): for a process about to exit.
    """
    held = _START_LOCK.acquire(timeout=_LOCK_WAIT_S)
    try:
        if for_good:
            _NO_MORE.append(True)
        children = multiprocessing.active_children()
        counted = {child.pid for child in children}
        uncounted = [popen for popen in list(_STARTED)
                     if popen.pid not in counted and popen.poll() is None]
    finally:
        if held:
            _START_LOCK.release()
    for popen in uncounted:  # started, not yet a child multiprocessing knows: never waited on
        popen.kill()
    for child in children:
        child.kill() if at_once else child.terminate()
    deadline = time.monotonic() + timeout_s
    for child in children:
        child.join(max(0.0, deadline - time.monotonic()))
    for child in children:
        if child.is_alive():
            child.kill()
            child.join(0.5)
    for popen in uncounted:
        popen.wait(0.5)


def exit_with_parent(parent_pid: int, every_s: float = 0.25) -> None:
    """
    In a worker: exit at once when ``parent_pid`` is no longer this process's parent.

    A pool worker waiting for work holds both ends of its queue's pipe, so it would wait for
    ever once the command is killed alone (SIGKILL, the OOM killer); a daemon thread looks
    every ``every_s`` seconds. Dask's workers watch their nanny with a pipe of their own.
    """
    def watch():
        while os.getppid() == parent_pid:
            time.sleep(every_s)
        os._exit(1)
    if os.getppid() != parent_pid:  # gone already
        os._exit(1)
    threading.Thread(target=watch, name='dq_fk exit with parent', daemon=True).start()


__all__ = ['exit_with_parent', 'prepare_children', 'run_with_sigint_blocked', 'signals_blocked',
           'stop_children']
