"""
Fixtures shared by every test: DDS isolation and process clean-up.

One fixture owns DDS isolation: the pytest process and every process a test starts run
with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and a ``ROS_DOMAIN_ID`` that no other test
run on this machine holds at the same time (a lock file per domain id).
"""

import os
import signal
import subprocess
import time

from dds_domains import acquire_private_domain_id
from hypothesis import HealthCheck, settings
import pytest

# Property-based fuzzing (hypothesis): a modest example count keeps `make test` fast; set
# DQ_FK_FUZZ=long for a deeper search (e.g. before a release, or after changing an input path).
settings.register_profile('ci', max_examples=60, deadline=None, derandomize=True,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile('long', max_examples=2000, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get('DQ_FK_FUZZ', 'ci'))


@pytest.fixture(scope='session', autouse=True)
def ros_domain_id():
    """Isolate DDS for the whole run: loopback discovery and a private domain id."""
    domain_id, lock = acquire_private_domain_id()
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
