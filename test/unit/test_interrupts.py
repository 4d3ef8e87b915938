"""The console scripts end quietly on a signal, whatever the signal interrupts."""

import signal
import subprocess
import sys
import textwrap

import pytest

# a command whose main() is interrupted while a class is made: Python 3.11 wraps the
# KeyboardInterrupt raised in __set_name__ in a RuntimeError (as when Ctrl-C lands while
# Dask's modules are imported)
COMMAND = """
import os
import signal


class Named:
    def __set_name__(self, owner, name):
        os.kill(os.getpid(), signal.{signal})
        for _ in range(10000):  # the handler runs at the next instruction
            pass


def main():
    class Layer:
        cached = Named()
    return 0
"""


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_an_interrupt_wrapped_in_another_error_still_exits_quietly(tmp_path, signum):
    (tmp_path / 'cut_command.py').write_text(textwrap.dedent(COMMAND.format(
        signal=signum.name)))
    run = subprocess.run(
        [sys.executable, '-c', 'import sys; sys.path.insert(0, sys.argv[1]); '
         'from dq_fk_ros.cli.interrupts import run; run("cut_command")', str(tmp_path)],
        capture_output=True, text=True, timeout=60)
    assert run.returncode == 128 + signum, run.stderr[-2000:]
    assert 'Traceback' not in run.stderr


def test_an_error_with_no_signal_is_still_shown(tmp_path):
    (tmp_path / 'failing_command.py').write_text('def main():\n    raise RuntimeError("x")\n')
    run = subprocess.run(
        [sys.executable, '-c', 'import sys; sys.path.insert(0, sys.argv[1]); '
         'from dq_fk_ros.cli.interrupts import run; run("failing_command")', str(tmp_path)],
        capture_output=True, text=True, timeout=60)
    assert run.returncode == 1 and 'RuntimeError: x' in run.stderr


def test_a_ros_program_interrupted_while_starting_exits_quietly(tmp_path):
    """As dq_fk_view's Ctrl-C while rclpy's modules are imported (exit 0 while starting)."""
    (tmp_path / 'cut_program.py').write_text(textwrap.dedent(COMMAND.format(signal='SIGINT')))
    run = subprocess.run(
        [sys.executable, '-c', 'import sys; sys.path.insert(0, sys.argv[1]); '
         'from dq_fk_ros.ros.executables import run_program; '
         'sys.exit(run_program("cut_program"))', str(tmp_path)],
        capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr[-2000:]
    assert 'Traceback' not in run.stderr
