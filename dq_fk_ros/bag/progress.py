"""A progress bar for the bag commands, on stderr."""

import sys
import time


class Progress:
    """
    A progress bar on stderr: ``[#####.....] done/total pct, msg/s, time left``.

    On a terminal it is redrawn in place (a carriage return) at most once a second.
    Elsewhere (a log file, a pipe, CI) it writes a whole line every
    :attr:`LOG_INTERVAL_S` seconds instead, so logs do not fill up. :meth:`update` with
    ``force`` writes the final line. Without a known total it shows the count and the rate.

    :param terminal: whether ``stream`` is a terminal (default: ``stream.isatty()``).
    """

    WIDTH = 30
    LOG_INTERVAL_S = 10.0

    def __init__(self, total, label, stream=None, enabled=True, clock=time.monotonic,
                 terminal=None):
        """Start the clock."""
        stream = sys.stderr if stream is None else stream
        self.total, self.label, self.stream, self.enabled = total, label, stream, enabled
        if terminal is None:
            isatty = getattr(stream, 'isatty', None)
            terminal = bool(isatty and isatty())
        self.terminal = terminal
        self.interval = 1.0 if terminal else self.LOG_INTERVAL_S
        self.clock = clock
        self.start = self.last = clock()
        self.shown = 0  # length of the line on screen, to blank a longer one

    def line(self, done, now) -> str:
        """Return the progress line for ``done`` messages at time ``now``."""
        rate = done / max(now - self.start, 1e-9)
        text = f'{self.label}: {done:,}'
        if self.total:
            share = min(done / self.total, 1.0)
            filled = int(round(share * self.WIDTH))
            left = (self.total - done) / rate if rate > 0 else 0.0
            text = (f'{self.label}: [{"#" * filled}{"." * (self.WIDTH - filled)}] '
                    f'{done:,}/{self.total:,} {100.0 * share:5.1f} %')
            return f'{text}, {rate:,.0f} msg/s, {max(left, 0.0):.0f} s left'
        return f'{text}, {rate:,.0f} msg/s'

    def update(self, done, force=False) -> None:
        """Show ``done`` messages if the interval has passed (or ``force``: final line)."""
        now = self.clock()
        if not self.enabled or (not force and now - self.last < self.interval):
            return
        self.last = now
        text = self.line(done, now)
        if not self.terminal:
            self.stream.write(text + '\n')
            self.stream.flush()
            return
        self.stream.write(text.ljust(self.shown) + ('\n' if force else '\r'))
        self.shown = 0 if force else len(text)
        self.stream.flush()
