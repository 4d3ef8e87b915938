"""
Ctrl-C and SIGTERM end a command quietly, at any moment: exit 130 or 143, no traceback.

:func:`run` is what the ``dq_fk_bag`` console script calls: it takes both signals before
the program's modules are imported (an import takes a third of a second), so a signal that
comes while Python is still loading them ends the command as one that comes later does.
Either signal raises ``KeyboardInterrupt`` in the main thread, so every ``finally`` and
``with`` on the way out runs (the fleet stops its workers, its state folder drops the work
of unfinished bags); a second signal while that runs ends the process at once.
Worker processes never see the terminal's Ctrl-C: the command stops them itself
(:mod:`dq_fk_ros.bag.child_processes`).
"""

import atexit
import importlib
import os
import signal
import sys

_received = []


def _on_signal(signum, frame):
    if _received:  # a second signal: the clean-up is taking too long for the user
        os._exit(128 + _received[0])
    _received.append(signum)
    raise KeyboardInterrupt


def take_signals() -> None:
    """Make SIGINT and SIGTERM raise ``KeyboardInterrupt`` (the first; a second exits)."""
    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)


def interrupted_code() -> int:
    """Return the exit status of an interrupted command: 128 + the signal (130: Ctrl-C)."""
    return 128 + (_received[0] if _received else signal.SIGINT)


def run(module: str = 'dq_fk_ros.cli.dq_fk_bag') -> None:
    """Take the signals, import ``module`` and exit with its ``main()``'s status."""
    take_signals()
    try:
        code = importlib.import_module(module).main()
    except KeyboardInterrupt:
        code = interrupted_code()
    except Exception:
        # After a signal, an error on the way out is the signal's: its KeyboardInterrupt can
        # come wrapped (Python 3.11 makes one raised in a class's __set_name__, while a
        # module such as Dask's is imported, a RuntimeError)
        if not _received:
            raise
        code = interrupted_code()
    # The work is done and saved. A signal from here on ends the process at once, with
    # 128 + the signal: while the exit hooks run (a Dask client's, logging's), and after
    # them, where Python's own shutdown would have reset the handlers and let the default
    # action kill the process (-2) instead.
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, _exit_now)
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe: nothing more can be said there
            pass
    os._exit(0 if code is None else code if isinstance(code, int) else 1)


def _exit_now(signum, frame):
    try:
        sys.stderr.flush()
    except (OSError, ValueError):
        pass
    os._exit(128 + signum)


def run_dq_fk_bag() -> None:
    """Run the ``dq_fk_bag`` console script."""
    run('dq_fk_ros.cli.dq_fk_bag')


__all__ = ['interrupted_code', 'run', 'run_dq_fk_bag', 'take_signals']
