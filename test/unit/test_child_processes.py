"""signals_blocked holds a signal back until the block ends, whichever thread takes it."""

import os
import signal
import threading
import time

from dq_fk_ros.bag.child_processes import signals_blocked
import pytest


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_a_signal_in_the_block_takes_effect_once_when_it_ends(signum):
    seen = []
    go = threading.Event()

    def send():  # a thread started before the block: the signal open there
        go.wait()
        os.kill(os.getpid(), signum)
    sender = threading.Thread(target=send)
    sender.start()
    saved = signal.signal(signum, lambda number, frame: seen.append((number, time.monotonic())))
    try:
        with signals_blocked():
            go.set()
            sender.join()
            for _ in range(100):  # Python runs pending handlers between these
                time.sleep(0.001)
            assert seen == []
            ended = time.monotonic()
        assert [number for number, _ in seen] == [signum]
        assert seen[0][1] >= ended
    finally:
        signal.signal(signum, saved)


def test_the_handlers_are_put_back():
    def handler(number, frame):
        pass
    saved = signal.signal(signal.SIGTERM, handler)
    try:
        with signals_blocked():
            assert signal.getsignal(signal.SIGTERM) is not handler
        assert signal.getsignal(signal.SIGTERM) is handler
    finally:
        signal.signal(signal.SIGTERM, saved)
