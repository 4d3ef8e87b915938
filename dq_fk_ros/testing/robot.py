"""
A robot under test: ``dq_fk_node`` and a joint source as child processes, TF read back here.

:class:`RobotFactory` is what the ``dq_fk_robot`` fixture gives a test:
``robot = dq_fk_robot('rl15', joints={'joint_2': 0.5})`` starts, on the test's domain,

* ``dq_fk_node`` for the robot (a shipped name, a DH file or a URDF/xacro; any node
  parameter as a keyword: ``publish_frequency=50.0``), under a node name of its own;
* a joint source (:mod:`dq_fk_ros.testing.joint_source`): fixed joints, changed at run time
  by :meth:`RobotHandle.set_joints`; or the rows of a CSV (``joints_csv=``), or a bag's
  JointStates (``joints_bag=``, through ``dq_fk_bag play``), replayed;

and reads ``/tf`` and ``/tf_static`` into :attr:`RobotHandle.buffer` (a
:class:`dq_fk_ros.tf.Buffer` fed by a listener in a context of its own). Every wait is for
an event with a deadline; every process is stopped at teardown, whatever the test's end.
Each robot of a test gets its own namespace (its joint states and node topics there); two
robots with the same frame names need ``frame_prefix=`` to be told apart on ``/tf``.
"""

import itertools
import json
import os
import queue
import subprocess
import sys
import tempfile
import threading
import time
from typing import TYPE_CHECKING

from dq_fk_ros.testing.processes import ProcessPool

if TYPE_CHECKING:
    from geometry_msgs.msg import TransformStamped

DEFAULT_TIMEOUT_S = 20.0
_counter = itertools.count()


class RobotError(AssertionError):
    """A robot under test did not come up or answer in time (one line and its log's tail)."""


def _ros_value(value) -> str:
    """Return a node parameter's value as ``-p name:=VALUE`` takes it (YAML)."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, (list, tuple)):
        return '[' + ', '.join(_ros_value(v) for v in value) + ']'
    if isinstance(value, str):
        return json.dumps(value)
    return repr(value)


class RobotHandle:
    """
    One robot under test (module doc); made by :class:`RobotFactory`.

    :attr:`buffer` holds its TF; :attr:`frames` the robot's frame ids on TF (its fixed frame,
    :attr:`fixed_frame`, first); :attr:`node`,
    :attr:`joints` its child processes (``Popen``); :attr:`namespace` its namespace.
    """

    def __init__(self, pool, robot, joints=None, joints_csv=None, joints_bag=None,
                 rate_hz=50.0, namespace=None, **params):
        """Start the node, the joint source and the listener (see :class:`RobotFactory`)."""
        from dq_fk_ros.description.loading import load_robot
        from dq_fk_ros.ros.executables import executable
        self._pool = pool
        self.robot = os.fspath(robot)
        self.namespace = '/' + (namespace or f'dq_fk_test_{os.getpid()}_{next(_counter)}')\
            .strip('/')
        loaded = load_robot(self.robot)
        self.joint_names = tuple(loaded.model.joint_names)
        prefix, model = params.get('frame_prefix', ''), loaded.model
        # (a DH file's fixed frame keeps its name under a prefix: robots share it)
        self.fixed_frame = model.tf_frame_id(model.fixed_frame, prefix)
        self.frames = (self.fixed_frame,) + tuple(prefix + f for f in model.frame_names)
        unknown = sorted(set(joints or {}) - set(self.joint_names))
        if unknown:
            raise RobotError(f'{self.robot}: no joint {unknown[0]!r}; its joints: '
                             f'{", ".join(self.joint_names)}')
        params.setdefault('robot_description_file', os.path.abspath(self.robot)
                          if os.path.exists(self.robot) else self.robot)
        argv = executable('dq_fk_node') + ['--ros-args', '--log-level', 'warn', '-r',
                                           f'__ns:={self.namespace}']
        for name, value in params.items():
            argv += ['-p', f'{name}:={_ros_value(value)}']
        topic = f'{self.namespace}/joint_states'
        # (its log to a file: a pipe nobody reads would stop a node that logs much)
        self._node_log = tempfile.TemporaryFile('w+', encoding='utf-8', errors='replace')
        self._start_listener()
        self.node = pool.start(argv, stdout=self._node_log)
        if joints_bag is not None or joints_csv is not None:
            self._wait_for_tf_match()   # a replay sends each row once: none lost before
        if joints_bag is not None:   # (once the node subscribed: nothing sent before)
            self.joints = pool.start(executable('dq_fk_bag') + [
                'play', os.fspath(joints_bag), '--output-topic', topic,
                '--wait-for-subscribers', '1', '--quiet'])
        else:
            argv = [sys.executable, '-m', 'dq_fk_ros.testing.joint_source', self.robot,
                    '--topic', topic, '--rate', str(rate_hz), '--set', json.dumps(joints or {})]
            if joints_csv is not None:
                argv += ['--csv', os.fspath(joints_csv)]
            self.joints = pool.start(argv, stdin=subprocess.PIPE)
        self._read_joint_lines = joints_bag is None
        self._said = queue.Queue()   # the joint source's lines, read by a thread of their own
        if self._read_joint_lines:
            threading.Thread(target=self._read_said, daemon=True,
                             name='dq_fk test joint source').start()

    def _read_said(self):
        """Hand every line the joint source prints to :meth:`_joint_line` (until it ends)."""
        for line in self.joints.stdout:
            self._said.put(line)

    # -- the listener --------------------------------------------------------------------
    def _start_listener(self):
        import rclpy
        from dq_fk_ros.ros.tf_buffer import Buffer
        from dq_fk_ros.ros.tf_listener import TransformListener
        self._context = rclpy.Context()
        rclpy.init(context=self._context)
        self._node = rclpy.create_node(f'dq_fk_test_listener_{os.getpid()}_{next(_counter)}',
                                       context=self._context, enable_rosout=False,
                                       start_parameter_services=False)
        self.buffer = Buffer()
        self._listener = TransformListener(self.buffer, self._node, spin_thread=True)

    def _wait_for_tf_match(self, timeout_s=30.0):
        """Wait until the listener's /tf subscription has matched this robot's node."""
        listener = self._listener
        sub = listener.tf_thread.subscription if listener.tf_thread else listener.tf_sub
        from dq_fk_ros.testing.topics import wait_until

        def matched():
            if self.node.poll() is not None:
                raise RobotError(f'{self.robot}: dq_fk_node ended (exit {self.node.returncode})'
                                 f': {self.node_log()[-300:]!r}')
            infos = self._node.get_publishers_info_by_topic('/tf')
            return any(i.node_namespace == self.namespace for i in infos) and \
                sub.get_publisher_count() >= len(infos)
        if wait_until(matched, timeout_s):
            return
        raise RobotError(f'{self.robot}: its /tf not matched by the listener within '
                         f'{timeout_s:g} s')

    def close(self) -> None:
        """Stop the listener and both processes (the fixture does this at teardown)."""
        listener, self._listener = getattr(self, '_listener', None), None
        if listener is not None:
            listener.unregister()
            self._node.destroy_node()
            self._context.try_shutdown()
        for proc in (self.joints, self.node):
            self._pool.stop(proc)
        self._node_log.close()

    # -- waiting -------------------------------------------------------------------------
    def node_log(self) -> str:
        """Return what dq_fk_node printed so far (its last 64 KiB)."""
        self._node_log.flush()
        self._node_log.seek(0, os.SEEK_END)
        size = self._node_log.tell()
        self._node_log.seek(max(0, size - 65536))
        return self._node_log.read()

    def _check_alive(self):
        for what, proc in (('dq_fk_node', self.node), ('the joint source', self.joints)):
            if proc.poll() is not None and not (what != 'dq_fk_node' and proc.returncode == 0):
                if proc is self.node:
                    tail = self.node_log()
                else:
                    tail = ''.join(self._said.queue)
                raise RobotError(f'{what} for {self.robot} ended (exit {proc.returncode}): '
                                 f'{tail.strip()[-1500:]}')

    def wait_for(self, target: str, source: str,
                 timeout: float = DEFAULT_TIMEOUT_S) -> 'TransformStamped':
        """
        Return ``source``'s pose in ``target`` (``TransformStamped``, latest) once TF has it.

        :raises RobotError: not within ``timeout`` s (one line: the frames TF has), or a
            process of the robot ended.
        """
        from rclpy.duration import Duration
        from rclpy.time import Time
        deadline = time.monotonic() + timeout
        while True:
            self._check_alive()
            if self.buffer.can_transform(target, source, Time(),
                                         timeout=Duration(seconds=0.1)):
                return self.buffer.lookup_transform(target, source, Time())
            if time.monotonic() > deadline:
                known = ', '.join(self.buffer.core.frame_names()[:20]) or 'none'
                raise RobotError(f'no transform from {source!r} to {target!r} within '
                                 f'{timeout:g} s; frames on /tf: {known}')

    def set_joints(self, joints: dict, timeout: float = DEFAULT_TIMEOUT_S) -> int:
        """
        Set joint positions (rad, m; the others keep theirs); return once TF shows them.

        Returns the stamp (ns) of the first JointState carrying them: every moving frame of
        :attr:`buffer` has a transform at or after it when this returns.
        """
        if not self._read_joint_lines:
            raise RobotError('this robot replays a bag: its joints are not set')
        unknown = sorted(set(joints) - set(self.joint_names))
        if unknown:
            raise RobotError(f'{self.robot}: no joint {unknown[0]!r}; its joints: '
                             f'{", ".join(self.joint_names)}')
        self.joints.stdin.write(json.dumps({k: float(v) for k, v in joints.items()}) + '\n')
        self.joints.stdin.flush()
        deadline = time.monotonic() + timeout
        line = self._joint_line(deadline, ('stamp ', 'error '))
        if not line.startswith('stamp '):
            raise RobotError(f'the joint source refused {joints}: {line}')
        stamp = int(line.split()[1])
        self._wait_tf_after(stamp, deadline, timeout)
        return stamp

    def wait_replayed(self, timeout: float = DEFAULT_TIMEOUT_S) -> int:
        """
        Return once a CSV's last row was published and TF shows it (``joints_csv=``).

        Returns the stamp (ns) of the last row's message.
        """
        deadline = time.monotonic() + timeout
        stamp = int(self._joint_line(deadline, ('done ',)).split()[1])
        self._wait_tf_after(stamp, deadline, timeout)
        return stamp

    def _joint_line(self, deadline, starts):
        if not self._read_joint_lines:
            raise RobotError('this robot replays a bag: its joint source says nothing')
        while True:
            self._check_alive()
            left = deadline - time.monotonic()
            if left <= 0:
                raise RobotError(f'the joint source did not say {starts[0].strip()!r} in time')
            try:
                line = self._said.get(timeout=min(left, 0.2))
            except queue.Empty:
                continue
            if line.startswith(starts):
                return line.strip()

    def _wait_tf_after(self, stamp, deadline, timeout):
        """Wait until every moving edge of this robot's frames has a sample at or after it."""
        def caught_up():
            with self.buffer.lock:
                core = self.buffer.core
                caches = [core.caches[core.ids[f]] for f in self.frames if f in core.ids]
                moving = [c for c in caches if c is not None and not c.static]
                return bool(moving) and all(c.newest_stamp() >= stamp for c in moving)
        while not caught_up():
            self._check_alive()
            if time.monotonic() > deadline:
                raise RobotError(f'TF did not show the joints set (stamp {stamp}) within '
                                 f'{timeout:g} s')
            self.buffer.wait_for_data(0.1)

    def pose(self, target: str, source: str,
             timeout: float = DEFAULT_TIMEOUT_S) -> 'TransformStamped':
        """Return ``source``'s latest pose in ``target`` (``TransformStamped``; waits for TF)."""
        return self.wait_for(target, source, timeout)


class RobotFactory:
    """
    What the ``dq_fk_robot`` fixture is: a callable that starts robots under test.

    ``dq_fk_robot(robot, joints=None, joints_csv=None, joints_bag=None, rate_hz=50.0,
    namespace=None, **node_parameters)`` returns a started :class:`RobotHandle`.

    All robots made are closed by :meth:`close_all` (the fixture's teardown).
    """

    def __init__(self, pool=None):
        """Make robots whose processes ``pool`` starts (default: a pool of its own)."""
        self._pool = pool or ProcessPool()
        self._robots = []
        self._lock = threading.Lock()

    def __call__(self, robot, **options) -> RobotHandle:
        """Start a robot (class doc)."""
        handle = RobotHandle(self._pool, robot, **options)
        with self._lock:
            self._robots.append(handle)
        return handle

    def close_all(self) -> None:
        """Close every robot made; then stop anything the pool still runs."""
        with self._lock:
            robots, self._robots = self._robots, []
        for handle in robots:
            handle.close()
        self._pool.stop_all()


__all__ = ['RobotError', 'RobotFactory', 'RobotHandle']
