"""
The lines a started process prints, read by a thread of their own and kept.

``select`` on the pipe and then ``readline`` loses lines: one ``readline`` may take several
lines into the file object's buffer, and ``select`` then waits for bytes that already came.
Here one thread per process reads every line into a queue; nothing read is dropped, so a line
printed before the one a test waits for (a mesh's problem before the view's address) is still
there for a later look.
"""

import queue
import threading
import time

_EOF = object()


class ProcessLines:
    """Every line of a process's merged stdout and stderr, in order, as they come."""

    def __init__(self, proc):
        self.lines = []      # every line taken so far
        self._given = 0      # how many of them new_lines has returned
        self._ended = False
        self._queue = queue.Queue()

        def pump():
            try:
                for line in iter(proc.stdout.readline, ''):
                    self._queue.put(line)
            except (OSError, ValueError):  # the pipe closed by the clean-up
                pass
            self._queue.put(_EOF)
        threading.Thread(target=pump, daemon=True).start()

    def _take(self, deadline):
        """Take the next line into ``lines`` and return it; None at the deadline or the end."""
        left = deadline - time.monotonic()
        if self._ended or left <= 0:
            return None
        try:
            line = self._queue.get(timeout=left)
        except queue.Empty:
            return None
        if line is _EOF:
            self._ended = True
            return None
        self.lines.append(line)
        return line

    def until(self, predicate, timeout_s):
        """Return the first line from here on that ``predicate`` accepts (None: none came)."""
        deadline = time.monotonic() + timeout_s
        while True:
            line = self._take(deadline)
            if line is None or predicate(line):
                return line

    def first(self, predicate, timeout_s):
        """
        Return the first line ever taken that ``predicate`` accepts, waiting for one to come.

        :meth:`until` reads from here on: a line the process printed before the one an
        earlier wait stopped at (a mesh's problem before the view's address) is among
        :attr:`lines` already, and only this finds it.
        """
        for line in self.lines:
            if predicate(line):
                return line
        return self.until(predicate, timeout_s)

    def new_lines(self, seconds):
        """Return the lines not returned by an earlier call, waiting ``seconds`` for more."""
        deadline = time.monotonic() + seconds
        while self._take(deadline) is not None:
            pass
        out, self._given = self.lines[self._given:], len(self.lines)
        return out


def process_lines(proc):
    """Return the :class:`ProcessLines` of a process started with a stdout pipe (one each)."""
    reader = getattr(proc, 'process_lines', None)
    if reader is None:
        reader = proc.process_lines = ProcessLines(proc)
    return reader
