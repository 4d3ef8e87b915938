"""
``dq_fk show ROBOT``: your robot with joints to move, in a browser (urdf_tutorial's display).

What ``ros2 launch urdf_tutorial display.launch.py model:=ROBOT`` gives on a full install
(robot_state_publisher, joint_state_publisher_gui, RViz), on pip-only: ``dq_fk_node`` with
the robot, and ``dq_fk_view --joint-panel`` whose page has a slider per moving joint (within
its limits; mimic joints follow; a reset) and publishes their ``sensor_msgs/JointState`` on
``joint_states``. ROBOT is a URDF or xacro file, a DH YAML file or a shipped robot's name; it
is loaded here first, so a robot that does not load is one line and nothing starts. The
address to open is printed once the page is served; Ctrl-C (or SIGTERM) stops every process
it started, each in a session of its own so that the terminal's Ctrl-C reaches this one only.

A xacro file is a program: it runs here once to check it and once in dq_fk_node, as the
user asked by naming it. Relative mesh paths of a URDF file resolve inside its folder
(``dq_fk_view --urdf-dir``). ``ROS_AUTOMATIC_DISCOVERY_RANGE`` unset is set to LOCALHOST
for the processes started: nothing leaves this machine unless the user says otherwise.
"""

import ctypes
import json
import os
import signal
import subprocess
import sys
import threading
import time

from dq_fk_ros.description.from_urdf import NODE_OPTIONS
from dq_fk_ros.description.loading import is_urdf, load_robot, resolve_robot
from dq_fk_ros.errors import DqFkError
from dq_fk_ros.ros.executables import executable

START_TIMEOUT_S = 30.0   # the page must be served by then
STOP_TIMEOUT_S = 10.0    # each process's time to stop after SIGINT; then it is killed
PR_SET_PDEATHSIG = 1     # linux/prctl.h
VIEW_OPEN = 'dq_fk_view: open '


def commands(robot: str, port: int, host: str = '127.0.0.1',
             packages: dict | None = None, base: str = '', tip: str = '') -> list:
    """
    Return ``[(name, argv)]`` of the processes that show ``robot`` (a path or shipped name).

    :param packages: ``{name: folder}`` for xacro ``$(find)`` and ``package://`` meshes.
    :param base: the URDF link the robot starts at ('' the root); ``tip``: where its first
        chain ends ('' the default of ``dq_fk from-urdf``).
    """
    path = resolve_robot(robot)
    packages = packages or {}
    quiet = ['--ros-args', '--log-level', 'warn']
    node = executable('dq_fk_node') + [
        '--ros-args', '-p', f'robot_description_file:={json.dumps(os.path.abspath(path))}']
    if packages:
        node += ['-p', 'package_paths:=' + json.dumps([f'{n}={d}' for n, d in packages.items()])]
    for name, value in (('urdf_base_link', base), ('urdf_tip_link', tip)):
        if value:
            node += ['-p', f'{name}:={json.dumps(value)}']
    view = executable('dq_fk_view') + ['--host', host, '--port', str(port), '--joint-panel']
    if is_urdf(path):
        view += ['--urdf-dir', os.path.dirname(os.path.abspath(path))]
    for name, folder in packages.items():
        view += ['--package', f'{name}={folder}']
    return [('dq_fk_node', node + quiet[1:]), ('dq_fk_view', view + quiet)]


def _death_signal():
    """
    Return what a child runs before ``exec``: SIGTERM it when this process dies.

    Even by SIGKILL (Linux ``prctl(PR_SET_PDEATHSIG)``), so a killed ``dq_fk show`` leaves no
    node holding the domain or view holding the port. The C library is looked up here, in
    the parent; None where there is no ``prctl`` (Ctrl-C and SIGTERM still stop them).
    """
    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None
    return lambda: prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)


class AddressWatcher:
    """Pass a child's output lines on; keep the address of ``dq_fk_view: open URL``."""

    def __init__(self, stream, out):
        """Read ``stream`` in a daemon thread, writing each line to ``out``."""
        self.address = None
        self._thread = threading.Thread(target=self._run, args=(stream, out), daemon=True)
        self._thread.start()

    def _run(self, stream, out):
        for line in stream:
            if self.address is None and line.startswith(VIEW_OPEN):
                self.address = line[len(VIEW_OPEN):].strip()
                continue  # said once, by show, with what the page has
            try:
                out.write(line)
                out.flush()
            except (OSError, ValueError):  # our stdout closed: keep draining the pipe
                pass


def _stop(procs) -> int:
    """SIGINT each process, wait, kill what did not stop; return 1 if any had to be killed."""
    rc = 0
    for _, proc in procs:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
    for name, proc in procs:
        try:
            proc.wait(timeout=STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            print(f'dq_fk show: {name} did not stop within {STOP_TIMEOUT_S:g} s: killed',
                  file=sys.stderr)
            proc.kill()
            proc.wait()
            rc = 1
    return rc


def show(robot: str, port: int, host: str = '127.0.0.1', packages: dict | None = None,
         base: str = '', tip: str = '', out=sys.stdout) -> int:
    """
    Check ``robot``, start the node and the view, print the address; return on Ctrl-C.

    :return: 0 after Ctrl-C or SIGTERM (130 if it came while the robot loads); 1 if the
        robot does not load (one line), a process ends on its own (its lines above, then
        one saying which) or the page is not served within ``START_TIMEOUT_S``.
    """
    # Ctrl-C and SIGTERM raise KeyboardInterrupt, also where a script's `dq_fk show &`
    # started with SIGINT ignored (bash does so for background jobs) or a parent blocked it
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})
    previous = (signal.signal(signal.SIGINT, signal.default_int_handler),
                signal.signal(signal.SIGTERM, signal.default_int_handler))
    try:
        return _show(robot, port, host, packages, base, tip, out)
    except KeyboardInterrupt:  # while loading the robot: nothing started yet
        return 130
    finally:
        signal.signal(signal.SIGINT, previous[0])
        signal.signal(signal.SIGTERM, previous[1])


def _show(robot, port, host, packages, base, tip, out) -> int:
    try:
        loaded = load_robot(robot, base or None, tip or None, packages=packages,
                            options=NODE_OPTIONS)
    except (DqFkError, OSError, ValueError) as exc:
        print(f'dq_fk show: {exc}', file=sys.stderr)
        return 1
    env = dict(os.environ)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    model = loaded.model
    print(f'dq_fk show: {model.name}, {len(model.joint_names)} joints; starting dq_fk_node '
          f"and dq_fk_view (ROS_DOMAIN_ID={env.get('ROS_DOMAIN_ID', '0')}, discovery "
          f"{env['ROS_AUTOMATIC_DISCOVERY_RANGE']})", file=out, flush=True)
    procs, watcher, on_fork = [], None, _death_signal()
    try:
        for name, argv in commands(robot, port, host, packages, base, tip):
            view = name == 'dq_fk_view'
            proc = subprocess.Popen(argv, env=env, start_new_session=True,
                                    preexec_fn=on_fork,
                                    stdout=subprocess.PIPE if view else None,
                                    text=True if view else None)
            procs.append((name, proc))
            if view:
                watcher = AddressWatcher(proc.stdout, out)
        code = _watch(procs, watcher, out)
    except KeyboardInterrupt:
        code = 0
    finally:
        killed = _stop(procs)   # nothing left running, whatever ended it
    return code or killed


def _watch(procs, watcher, out) -> int:
    """Print the address once the page is served; return 1 when a process ends or it is late."""
    deadline = time.monotonic() + START_TIMEOUT_S
    announced = False
    while True:
        for name, proc in procs:
            if proc.poll() is not None:
                print(f'dq_fk show: {name} ended (exit code {proc.returncode}); stopping',
                      file=sys.stderr)
                return 1
        if not announced:
            if watcher.address:
                print(f'dq_fk show: open {watcher.address} (a slider per moving joint; '
                      'Ctrl-C stops)', file=out, flush=True)
                announced = True
            elif time.monotonic() > deadline:
                print(f'dq_fk show: dq_fk_view did not start within {START_TIMEOUT_S:g} '
                      's; stopping', file=sys.stderr)
                return 1
        time.sleep(0.1)


__all__ = ['commands', 'show', 'START_TIMEOUT_S']
