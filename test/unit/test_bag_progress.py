"""The progress bar of dq_fk_bag, driven by a fake clock."""

import io

from dq_fk_ros.bag.progress import Progress


class FakeClock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def test_bar_rate_and_time_left():
    clock, out = FakeClock(), io.StringIO()
    meter = Progress(1000, 'process', stream=out, clock=clock, terminal=True)
    clock.now += 2.0
    meter.update(250)
    assert out.getvalue() == ('process: [########......................] 250/1,000  25.0 %, '
                              '125 msg/s, 6 s left\r')


def test_redraws_at_most_once_a_second_and_ends_the_line():
    clock, out = FakeClock(), io.StringIO()
    meter = Progress(10, 'play', stream=out, clock=clock, terminal=True)
    clock.now += 0.5
    meter.update(1)
    assert out.getvalue() == ''
    clock.now += 0.5
    meter.update(5)
    clock.now += 0.1
    meter.update(10, force=True)
    first, final = out.getvalue().split('\r')
    assert first.startswith('play: [###############...............] 5/10')
    assert final.startswith('play: [##############################] 10/10 100.0 %')
    assert final.endswith('0 s left\n') and len(final) - 1 >= len(first)


def test_unknown_total_and_disabled():
    clock, out = FakeClock(), io.StringIO()
    meter = Progress(0, 'process', stream=out, clock=clock)
    clock.now += 1.0
    meter.update(1234, force=True)
    assert out.getvalue() == 'process: 1,234, 1,234 msg/s\n'
    quiet = io.StringIO()
    Progress(10, 'x', stream=quiet, enabled=False, clock=clock).update(5, force=True)
    assert quiet.getvalue() == ''


def test_not_a_terminal_gets_a_whole_line_every_ten_seconds():
    """A log file or CI: no carriage returns, no line per second."""
    clock, out = FakeClock(), io.StringIO()
    meter = Progress(100, 'process', stream=out, clock=clock)  # StringIO is not a tty
    for _ in range(25):
        clock.now += 1.0
        meter.update(4)
    meter.update(100, force=True)
    lines = out.getvalue().split('\n')
    assert '\r' not in out.getvalue() and lines[-1] == ''
    assert len(lines) - 1 == 3  # at 10 s, 20 s, and the final line
    assert lines[2].startswith('process: [##############################] 100/100')
