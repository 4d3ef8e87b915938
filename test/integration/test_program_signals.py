"""
A program started by a script (``prog &``, then ``kill -INT``) stops on SIGINT at any moment.

bash starts a script's background job with SIGINT ignored, and a parent may hand its
children SIGINT blocked (this test blocks it, as a thread that starts processes might):
without ``executables.take_sigint`` a SIGINT that came before rclpy took the signal was lost
and the program ran on (seen in CI with the README's ``dq_fk_view --port 0 &``).
"""

import os
import signal
import subprocess

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PROGRAMS = {
    'dq_fk_node': ['--ros-args', '-p', 'robot_description_file:=rl15',
                   '-r', '__node:=signal_test_node'],
    'fake_joint_publisher': ['--ros-args', '-p', 'robot_description_file:=rl15',
                             '-r', '__node:=signal_test_fake'],
    'dq_fk_view': ['--port', '0'],
    'dq_fk_foxglove': ['--port', '0'],
}


def _block_sigint():
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})


@pytest.mark.parametrize('after_s', [0.3, 2.0], ids=['while-starting', 'started'])
@pytest.mark.parametrize('program', sorted(PROGRAMS))
def test_sigint_to_a_background_job_stops_it_quietly(program, after_s, ros_domain_id):
    argv = ' '.join([os.path.join(ROOT, '.venv', 'bin', program)] + PROGRAMS[program])
    script = f'{argv} &\nsleep {after_s}\nkill -INT %1\nwait %1'
    proc = subprocess.Popen(['bash', '-c', script], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True,
                            preexec_fn=_block_sigint)
    try:
        output, _ = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        output, _ = proc.communicate()
        pytest.fail(f'{program}: still running 30 s after SIGINT at {after_s} s\n{output}')
    assert proc.returncode == 0, f'{program}: exit {proc.returncode}\n{output}'
    assert 'Traceback' not in output, output
