"""signals_blocked holds a signal back till the block ends; a stop for good ends worker starts."""

import os
import signal
import subprocess
import sys
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


FOR_GOOD = """
import multiprocessing
import threading
import time

from dq_fk_ros.bag.child_processes import prepare_children, stop_children

if __name__ == '__main__':
    prepare_children()
    ctx = multiprocessing.get_context('spawn')
    worker = ctx.Process(target=time.sleep, args=(60,))
    worker.start()
    stop_children(at_once=True, for_good=True)
    assert worker.exitcode == -9, worker.exitcode
    try:
        ctx.Process(target=time.sleep, args=(60,)).start()
    except RuntimeError as exc:
        print('main thread:', exc)
    starter = threading.Thread(target=ctx.Process(target=time.sleep, args=(60,)).start,
                               daemon=True)
    starter.start()
    starter.join(0.5)
    print('other thread waits:', starter.is_alive())
    print('children:', multiprocessing.active_children())
"""


def test_after_a_stop_for_good_no_worker_starts(tmp_path):
    """The workers are killed; the main thread is told in one line; another thread waits."""
    script = tmp_path / 'for_good.py'
    script.write_text(FOR_GOOD)
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, done.stderr[-2000:]
    lines = done.stdout.splitlines()
    assert lines[0].startswith('main thread: no worker process can start: '), lines
    assert lines[1:] == ['other thread waits: True', 'children: []'], lines
