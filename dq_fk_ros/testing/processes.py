"""
Child processes of a test: started in a session of their own, every one stopped at the end.

:class:`ProcessPool` starts programs with the test's isolated environment (its domain, on
loopback) and stops them all: SIGINT to each process group, SIGKILL to what is left after
``grace_s``. On Linux each child is also asked to get SIGTERM if the test process dies
(``PR_SET_PDEATHSIG``), so that even a pytest killed with SIGKILL leaves no node running on
the domain; Linux ties that to the thread that started the child, so a process must be
started from a thread that outlives it (the test's own). SIGINT and SIGTERM are given back
their default in the child: a pytest started with SIGINT ignored (a CI runner, a background
job) would otherwise hand that on, and its children would not stop on SIGINT. Plain Python,
no ROS.
"""

import ctypes
import os
import signal
import subprocess
import time

_PR_SET_PDEATHSIG = 1


def _child_signals():   # (runs in the child between fork and exec)
    """Die with the parent; take SIGINT and SIGTERM as a terminal's child would."""
    try:
        libc = ctypes.CDLL(None)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
        # a pytest started with SIGINT ignored (a CI runner, a background job) hands that on
        # through exec: its children would not stop on stop()'s SIGINT (nor a Python child
        # raise KeyboardInterrupt); libc's signal(), as Python's may not run in this thread
        for number in (signal.SIGINT, signal.SIGTERM):
            libc.signal(int(number), ctypes.c_void_p(0))   # SIG_DFL
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})
    except (OSError, AttributeError, ValueError):
        pass


class ProcessPool:
    """Start processes in their own session with the isolated environment; reap them all."""

    def __init__(self, env=None, grace_s: float = 5.0):
        """
        Start none yet.

        :param env: the environment every process gets (default: this process's, as it is
            when each one starts).
        :param grace_s: how long :meth:`stop_all` waits after SIGINT before SIGKILL.
        """
        self._env = env
        self.grace_s = grace_s
        self._procs = []

    def start(self, argv, **kwargs) -> subprocess.Popen:
        """Start ``argv`` (stdout and stderr merged, text) and remember it for clean-up."""
        env = dict(os.environ if self._env is None else self._env)
        env.update(kwargs.pop('env', {}) or {})
        kwargs.setdefault('stdout', subprocess.PIPE)
        kwargs.setdefault('stderr', subprocess.STDOUT)
        kwargs.setdefault('text', True)
        proc = subprocess.Popen(argv, env=env, start_new_session=True,
                                preexec_fn=_child_signals if os.name == 'posix' else None,
                                **kwargs)
        self._procs.append(proc)
        return proc

    def start_program(self, program: str, *params: str, node_name: str | None = None,
                      namespace: str | None = None, log_level: str = 'warn',
                      options=(), env=None) -> subprocess.Popen:
        """
        Start one of the package's programs (``dq_fk_node``, ``dq_fk_view``, ...).

        :param params: ROS parameters as ``name:=value`` (each one a ``-p``).
        :param node_name: a name for the program's node (the one named as the program: a
            program's helper nodes keep theirs); keep names apart where several of one
            program run on the domain.
        :param namespace: the node's namespace (its topics and its joint states under it;
            ``left``, ``/left`` and ``/left/`` are one).
        :param options: the program's own arguments, before ``--ros-args``.
        :returns: the process, with ``node_name`` and ``namespace`` set (None, '' if not
            given).
        """
        from dq_fk_ros.ros.executables import executable
        argv = executable(program) + list(options) + ['--ros-args', '--log-level', log_level]
        if node_name:
            argv += ['-r', f'{program}:__node:={node_name}']
        namespace = '/' + namespace.strip('/') if namespace and namespace.strip('/') else ''
        if namespace:
            argv += ['-r', f'__ns:={namespace}']
        for param in params:
            argv += ['-p', param]
        proc = self.start(argv, env=dict(env or {}))
        proc.node_name = node_name
        proc.namespace = namespace
        return proc

    def stop(self, proc) -> None:
        """Stop one process (its group): SIGINT, then SIGKILL after ``grace_s``."""
        _signal_group(proc, signal.SIGINT)
        try:
            proc.wait(timeout=self.grace_s)
        except subprocess.TimeoutExpired:
            pass
        _signal_group(proc, signal.SIGKILL)
        proc.wait()

    def stop_all(self) -> None:
        """SIGINT each process group, then SIGKILL whatever is still alive after ``grace_s``."""
        for proc in self._procs:
            _signal_group(proc, signal.SIGINT)
        deadline = time.monotonic() + self.grace_s
        for proc in self._procs:
            try:
                proc.wait(timeout=max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                pass
            _signal_group(proc, signal.SIGKILL)
            proc.wait()
            for stream in (proc.stdin, proc.stdout, proc.stderr):
                if stream is not None:
                    stream.close()
        self._procs = []


def _signal_group(proc, sig):
    try:
        os.killpg(proc.pid, sig)
    except (ProcessLookupError, PermissionError):
        pass


__all__ = ['ProcessPool']
