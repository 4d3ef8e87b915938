"""
Fixtures shared by every test: DDS isolation and process clean-up.

One fixture owns DDS isolation: the pytest process and every process a test starts run
with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and a ``ROS_DOMAIN_ID`` that no other test
run on this machine holds at the same time (a lock file per domain id).
"""

import fcntl
import os
import signal
import subprocess
import tempfile
import time

from hypothesis import HealthCheck, settings
import pytest

# Property-based fuzzing (hypothesis): a modest example count keeps `make test` fast; set
# DQ_FK_FUZZ=long for a deeper search (e.g. before a release, or after changing an input path).
settings.register_profile('ci', max_examples=60, deadline=None, derandomize=True,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile('long', max_examples=2000, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get('DQ_FK_FUZZ', 'ci'))

# Domain ids 1..101 keep the DDS ports below Linux's ephemeral range.
_DOMAIN_IDS = range(1, 102)


# DDS's well-known ports (the RTPS spec's, Fast DDS's and Cyclone's defaults): domain d
# uses UDP ports 7400 + 250 d + 0..249 (discovery and user traffic of its participants)
_PORT_BASE, _DOMAIN_GAIN = 7400, 250


def bound_udp_ports():
    """Return the UDP ports bound on this machine, any address (from /proc/net/udp, udp6)."""
    ports = set()
    for table in ('/proc/net/udp', '/proc/net/udp6'):
        try:
            with open(table, encoding='ascii') as stream:
                next(stream, None)
                for line in stream:
                    local = line.split()[1]
                    ports.add(int(local.rsplit(':', 1)[1], 16))
        except (OSError, ValueError, IndexError):
            continue
    return ports


def domain_in_use(domain_id, ports=None):
    """Say whether a DDS participant (anyone's) holds a port of ``domain_id`` on this machine."""
    low = _PORT_BASE + _DOMAIN_GAIN * domain_id
    ports = bound_udp_ports() if ports is None else ports
    return any(low <= port < low + _DOMAIN_GAIN for port in ports)


def _acquire_private_domain_id():
    """
    Lock and return a domain id no other test run on this machine is using.

    A domain where a participant this run did not start is seen (another user's node, a
    robot's stack) is skipped, lock or not: the tests talk only to what they started.
    """
    lock_dir = os.path.join(tempfile.gettempdir(), 'dq_fk_ros-ros-domains')
    os.makedirs(lock_dir, exist_ok=True)
    start = os.getpid() % len(_DOMAIN_IDS)
    for k in range(len(_DOMAIN_IDS)):
        domain_id = _DOMAIN_IDS[(start + k) % len(_DOMAIN_IDS)]
        handle = open(os.path.join(lock_dir, f'{domain_id}.lock'), 'w')
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        if domain_in_use(domain_id):
            handle.close()
            continue
        return domain_id, handle
    raise RuntimeError(f'no free ROS_DOMAIN_ID in {_DOMAIN_IDS} (all locked in {lock_dir})')


@pytest.fixture(scope='session', autouse=True)
def ros_domain_id():
    """Isolate DDS for the whole run: loopback discovery and a private domain id."""
    domain_id, lock = _acquire_private_domain_id()
    saved = {k: os.environ.get(k) for k in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE')}
    os.environ['ROS_DOMAIN_ID'] = str(domain_id)
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    os.environ.pop('ROS_STATIC_PEERS', None)
    yield domain_id
    for key, value in saved.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value
    lock.close()


class ProcessPool:
    """Start processes in their own session with the isolated environment; reap them all."""

    def __init__(self, env):
        self._env = env
        self._procs = []

    def start(self, argv, **kwargs):
        """Start ``argv`` (stdout and stderr merged, text) and remember it for clean-up."""
        env = dict(self._env)
        env.update(kwargs.pop('env', {}))
        proc = subprocess.Popen(
            argv, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            start_new_session=True, **kwargs)
        self._procs.append(proc)
        return proc

    def stop_all(self):
        """SIGINT each process group, then SIGKILL whatever is still alive after 5 s."""
        for proc in self._procs:
            _signal_group(proc, signal.SIGINT)
        deadline = time.monotonic() + 5.0
        for proc in self._procs:
            try:
                proc.wait(timeout=max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                pass
            _signal_group(proc, signal.SIGKILL)
            proc.wait()
            if proc.stdout is not None:
                proc.stdout.close()


def _signal_group(proc, sig):
    try:
        os.killpg(proc.pid, sig)
    except (ProcessLookupError, PermissionError):
        pass


@pytest.fixture
def processes(ros_domain_id):
    """Start processes that see only this test run's DDS domain; all killed at teardown."""
    pool = ProcessPool(dict(os.environ))
    try:
        yield pool
    finally:
        pool.stop_all()
