"""
A ROS domain id for one test process: held for it alone on this machine, on loopback.

Two things say a domain is taken, and both are checked:

* **a lock** (``flock`` on ``<tmp>/dq_fk_ros-ros-domains/<id>.lock``), which every test
  process using this package takes, and ROS's own ``domain_coordinator`` port (TCP
  ``32768 + id``, what launch_testing and ``ros2 test`` hold), bound on 127.0.0.1 so that a
  launch test beside ours never gets the same id. Both are released by the kernel when the
  process ends, however it ends.
* **a participant already on it**: any process with a DDS port of that domain bound (a
  robot's stack, another user's node, the orphans of a run that was killed) makes it taken,
  lock or not, since a test must talk only to the processes it started.

Why not ``domain_coordinator`` alone (``ros-jazzy-domain-coordinator``): its port is the
only claim it knows, so a domain used by a process that did not ask it (the orphans of a
killed run, a robot on the machine) is handed out; and its context manager catches an
``OSError`` raised inside the ``with`` block and tries the next id, turning the test's own
error into "generator didn't stop after throw()". Its port is still taken here, so the two
kinds of test runs coordinate. Ids 1 to 101 keep the DDS ports below Linux's ephemeral
range (Fast DDS refuses ids above 232). Plain Python, no ROS.
"""

import fcntl
import os
import socket
import tempfile

DOMAIN_IDS = range(1, 102)
COORDINATOR_PORT_BASE = 32768   # domain_coordinator's: it binds 32768 + id
# DDS's well-known ports (the RTPS spec's, Fast DDS's and Cyclone's defaults): domain d
# uses UDP ports 7400 + 250 d + 0..249 (discovery and user traffic of its participants)
_PORT_BASE, _DOMAIN_GAIN = 7400, 250


def bound_udp_ports() -> set:
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


def domain_in_use(domain_id: int, ports=None) -> bool:
    """Say whether a DDS participant (anyone's) holds a port of ``domain_id`` on this machine."""
    low = _PORT_BASE + _DOMAIN_GAIN * domain_id
    ports = bound_udp_ports() if ports is None else ports
    return any(low <= port < low + _DOMAIN_GAIN for port in ports)


class DomainClaim:
    """A domain id held by this process: its lock file and domain_coordinator's port."""

    def __init__(self, domain_id, lock, port):
        self.domain_id, self._lock, self._port = domain_id, lock, port

    def release(self) -> None:
        """Give the id back (also done by the kernel when the process ends)."""
        for held in (self._lock, self._port):
            if held is not None:
                held.close()
        self._lock = self._port = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()


def _coordinator_port(domain_id):
    """Bind domain_coordinator's port of ``domain_id`` on loopback; None if it is taken."""
    held = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        held.bind(('127.0.0.1', COORDINATOR_PORT_BASE + domain_id))
    except OSError:
        held.close()
        return None
    return held


def claim_domain(lock_dir: str | None = None) -> DomainClaim:
    """
    Return a :class:`DomainClaim` of an id no other process on this machine holds or uses.

    :raises RuntimeError: every id of ``DOMAIN_IDS`` is taken (one line).
    """
    lock_dir = lock_dir or os.path.join(tempfile.gettempdir(), 'dq_fk_ros-ros-domains')
    os.makedirs(lock_dir, exist_ok=True)
    start = os.getpid() % len(DOMAIN_IDS)
    for k in range(len(DOMAIN_IDS)):
        domain_id = DOMAIN_IDS[(start + k) % len(DOMAIN_IDS)]
        lock = open(os.path.join(lock_dir, f'{domain_id}.lock'), 'w')
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        port = _coordinator_port(domain_id)
        if port is None or domain_in_use(domain_id):
            lock.close()
            if port is not None:
                port.close()
            continue
        return DomainClaim(domain_id, lock, port)
    raise RuntimeError(f'no free ROS_DOMAIN_ID in {DOMAIN_IDS.start}..{DOMAIN_IDS.stop - 1} '
                       f'(all locked in {lock_dir}, held by launch tests or in use)')


ISOLATION = {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}   # and ROS_DOMAIN_ID
CLEARED = ('ROS_STATIC_PEERS', 'ROS_LOCALHOST_ONLY', 'FASTRTPS_DEFAULT_PROFILES_FILE',
           'FASTDDS_DEFAULT_PROFILES_FILE')


def isolate_environment(environ, domain_id: int) -> dict:
    """
    Set ``environ`` for ``domain_id`` on loopback; return what it held before (to restore).

    Peers and profiles that could reach beyond loopback (``ROS_STATIC_PEERS``, a Fast DDS
    profile file) are removed.
    """
    keys = ('ROS_DOMAIN_ID',) + tuple(ISOLATION) + CLEARED
    saved = {k: environ.get(k) for k in keys}
    environ['ROS_DOMAIN_ID'] = str(domain_id)
    environ.update(ISOLATION)
    for key in CLEARED:
        environ.pop(key, None)
    return saved


def restore_environment(environ, saved: dict) -> None:
    """Put back what :func:`isolate_environment` changed."""
    for key, value in saved.items():
        if value is None:
            environ.pop(key, None)
        else:
            environ[key] = value


__all__ = ['bound_udp_ports', 'claim_domain', 'domain_in_use', 'DomainClaim', 'DOMAIN_IDS',
           'isolate_environment', 'restore_environment']
