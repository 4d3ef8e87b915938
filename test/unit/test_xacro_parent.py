"""
The xacro sandbox's parent side with a stand-in child: what it asks, how it reads the answer.

test_xacro_sandbox.py runs the real child; here ``subprocess.Popen`` is replaced, so that
each return code, output and error text the child can give is read as it is meant to be.
"""

import json
import os
import signal
import subprocess
import sys

from dq_fk_ros.description import xacro_sandbox
from dq_fk_ros.description.packages import python_prefixes
from dq_fk_ros.description.xacro_sandbox import (
    check_expression, default_read_roots, expand_xacro, MAX_OUTPUT_BYTES, ros_package_roots,
    XacroRefused)
import pytest


class Child:
    """A stand-in for the child process: answers ``communicate`` as it is told."""

    made = []

    def __init__(self, args, **kwargs):
        self.args, self.kwargs = args, kwargs
        self.pid, self.returncode = 4321, None
        self.requests, self.timeouts = [], []
        self.answer = Child.answer   # (stdout, stderr, returncode), or None: never finishes
        Child.made.append(self)

    def communicate(self, request=None, timeout=None):
        self.requests.append(request)
        self.timeouts.append(timeout)
        if self.answer is None:
            raise subprocess.TimeoutExpired(self.args, timeout)
        out, err, self.returncode = self.answer
        return out, err

    def poll(self):
        return self.returncode


@pytest.fixture
def child(monkeypatch):
    """Return a function that sets the stand-in child's answer; its kills are recorded."""
    Child.made, Child.answer = [], (b'<robot/>', b'', 0)
    killed = []
    monkeypatch.setattr(xacro_sandbox.subprocess, 'Popen', Child)
    monkeypatch.setattr(xacro_sandbox.os, 'killpg', lambda pid, sig: killed.append((pid, sig)))

    def answer(out=b'', err=b'', returncode=0, never=False):
        Child.answer = None if never else (out, err, returncode)
        return Child.made, killed
    return answer


def refusal(path, **kwargs):
    with pytest.raises(XacroRefused) as caught:
        expand_xacro(path, ['/r'], **kwargs)
    return str(caught.value)


def test_the_child_is_started_alone_in_the_files_folder_and_asked_once(tmp_path, child,
                                                                       monkeypatch):
    made, killed = child(b'<robot name="r"/>')
    monkeypatch.setenv('ROS_DISTRO', 'jazzy')
    monkeypatch.setenv('DQ_FK_TEST_SECRET', 'hunter2')
    os.symlink(tmp_path, tmp_path / 'link')
    path = tmp_path / 'r.urdf.xacro'
    assert expand_xacro(path, [str(tmp_path / 'link' / '.')], 2.5, 3 << 20,
                        packages={'p': '/p'}, within=['/w']) == '<robot name="r"/>'
    (one,) = made
    assert one.args == [sys.executable, '-m', 'dq_fk_ros.description.xacro_sandbox']
    kwargs = dict(one.kwargs)
    env = kwargs.pop('env')
    assert env['ROS_DISTRO'] == 'jazzy' and 'DQ_FK_TEST_SECRET' not in env
    assert set(env) <= set(xacro_sandbox.ENVIRONMENT)
    assert kwargs == {'stdin': subprocess.PIPE, 'stdout': subprocess.PIPE,
                      'stderr': subprocess.PIPE, 'close_fds': True,
                      'start_new_session': True, 'cwd': str(tmp_path)}
    request = json.loads(one.requests[0])
    assert request == {'path': str(path), 'roots': sorted({str(tmp_path),
                                                          str(tmp_path / 'link')}),
                       'time_limit_s': 2.5, 'memory': 3 << 20, 'packages': {'p': '/p'},
                       'within': ['/w']}
    assert json.loads(made[0].requests[0])['path'] == str(path)
    assert killed == []   # it had finished: nothing to kill


@pytest.mark.parametrize('err, returncode, said', [
    (b'', -9, 'xacro was stopped by signal 9 (over the 3 MiB memory limit?)'),
    (b'first\nout of memory\n', -9, 'out of memory'),   # the child's own line first
    (b'', 3, 'xacro exited with 3'),
    (b'one\n\nthe last line \xff  \n', 1, 'the last line \ufffd'),
    (b'x' * 600, 1, 'x' * 500),
])
def test_each_failure_of_the_child_is_one_line(tmp_path, child, err, returncode, said):
    child(b'', err, returncode)
    assert refusal(tmp_path / 'r.xacro', memory_limit_bytes=3 << 20) == said


def test_the_output_is_bounded_and_must_be_utf8(tmp_path, child):
    child(b'x' * MAX_OUTPUT_BYTES)
    assert len(expand_xacro(tmp_path / 'r.xacro', ['/r'])) == MAX_OUTPUT_BYTES
    child(b'x' * (MAX_OUTPUT_BYTES + 1))
    assert refusal(tmp_path / 'r.xacro') == \
        f'the expanded URDF is larger than {MAX_OUTPUT_BYTES >> 20} MiB'
    child(b'<robot name="\xff"/>')
    assert refusal(tmp_path / 'r.xacro') == 'the expanded URDF is not UTF-8'


def test_the_wait_is_one_slice_unless_someone_may_stop_it(tmp_path, child):
    made, _ = child(b'<robot/>')
    expand_xacro(tmp_path / 'r.xacro', ['/r'], time_limit_s=5.0)
    assert 4.0 < made[-1].timeouts[0] <= 5.0   # the whole time limit at once
    expand_xacro(tmp_path / 'r.xacro', ['/r'], time_limit_s=5.0, should_stop=lambda: False)
    assert made[-1].timeouts[0] == 0.1   # slices, so that should_stop is asked
    expand_xacro(tmp_path / 'r.xacro', ['/r'], time_limit_s=0.05, should_stop=lambda: False)
    assert 0.0 < made[-1].timeouts[0] <= 0.05   # never past the deadline


def test_a_child_that_never_answers_is_stopped_and_killed(tmp_path, child):
    made, killed = child(never=True)
    assert refusal(tmp_path / 'r.xacro', time_limit_s=0.05) == \
        'xacro took longer than 0.05 s; stopped (a macro that expands without end?)'
    assert made[-1].requests[1:] and not any(made[-1].requests[1:])   # sent once only
    assert killed == [(4321, signal.SIGKILL)]
    assert made[-1].timeouts[-1] == 5.0   # the reaping waits, but not for ever
    stops = iter([False, True])
    assert refusal(tmp_path / 'r.xacro', should_stop=lambda: next(stops)) == \
        'xacro stopped: shutting down'
    assert len(made[-1].requests) == 3 and len(killed) == 2


def test_check_expression_says_what_it_refuses_in_sixty_and_forty_characters():
    text = 'x.' + '__' + 'y' * 70
    with pytest.raises(XacroRefused) as caught:
        check_expression(text)
    assert str(caught.value) == (f'expression {text[:60]!r} uses {text[2:42]!r}: names with '
                                 f'__ reach Python internals and are not evaluated')
    for text in ('a = 1', 'import os', '(' * 3 + 'b' * 70):   # statements are not expressions
        with pytest.raises(XacroRefused) as caught:
            check_expression(text)
        assert str(caught.value) == f'not a valid expression: {text[:60]!r}'


def test_the_package_roots_come_from_the_environment_given():
    environ = {'AMENT_PREFIX_PATH': os.pathsep.join(['/a', '', '/b']),
               'ROS_PACKAGE_PATH': os.pathsep.join(['/c', '/d e', ''])}
    shares = [os.path.join(p, 'share') for p in python_prefixes()]
    assert ros_package_roots(environ) == ['/a/share', '/b/share', '/c', '/d e'] + shares
    assert ros_package_roots({}) == shares


def test_the_default_read_roots_end_with_the_extra_folders(tmp_path):
    roots = default_read_roots(tmp_path / 'r.xacro', [tmp_path / 'x', '/y'])
    assert roots[0] == str(tmp_path) and roots[-2:] == [str(tmp_path / 'x'), '/y']
