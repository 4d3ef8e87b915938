"""A progress bar for the bag commands, on stderr."""

import sys
import time


class Progress:
    """
    A progress bar on stderr: ``[#####.....] done/total pct, msg/s, time left``.

    Redrawn in place (a carriage return) at most once a second; :meth:`update` with
    ``force`` ends the line. Without a known total it shows the count and the rate only.
    """

    WIDTH = 30

    def __init__(self, total, label, stream=sys.stderr, enabled=True, clock=time.monotonic):
        """Start the clock."""
        self.total, self.label, self.stream, self.enabled = total, label, stream, enabled
        self.clock = clock
        self.start = self.last = clock()
        self.shown = 0  # length of the line on screen, to blank a longer one

    def line(self, done, now):
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

    def update(self, done, force=False):
        """Redraw for ``done`` messages if a second has passed (or ``force``: final line)."""
        now = self.clock()
        if not self.enabled or (not force and now - self.last < 1.0):
            return
        self.last = now
        text = self.line(done, now)
        self.stream.write(text.ljust(self.shown) + ('\n' if force else '\r'))
        self.shown = 0 if force else len(text)
        self.stream.flush()
